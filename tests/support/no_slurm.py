"""The test session's PATH without SLURM's commands, so that every test fakes the SLURM commands it touches.

On a machine where SLURM is installed a test that forgets to fake one (the suite once needed a real `srun`:
submitit looks for it before submitting anything) would pass there and fail on every machine without SLURM.
`path_without_slurm` rebuilds PATH so that no SLURM command is found, whatever is installed: each PATH folder
that holds one is replaced by a shadow folder of symbolic links to its other entries. Tests that need a SLURM
command put their fake in a folder of their own in front of PATH.
"""
from __future__ import annotations

import os
from pathlib import Path

SLURM_COMMANDS = ("sbatch", "srun", "squeue", "sacct", "scancel", "sinfo", "scontrol", "salloc", "sstat",
                  "sattach", "sbcast", "sacctmgr", "sprio", "sshare", "sreport", "strigger")


def path_without_slurm(path: str, shadow_root: Path) -> str:
    """`path` (a PATH value) with every folder holding a SLURM command replaced by a shadow folder under
    `shadow_root` that links to the folder's other entries."""
    folders = []
    for index, folder in enumerate(path.split(os.pathsep)):
        if folder and any(os.path.lexists(os.path.join(folder, name)) for name in SLURM_COMMANDS):
            shadow = shadow_root / str(index)
            shadow.mkdir(parents=True, exist_ok=True)
            for entry in os.scandir(folder):
                if entry.name not in SLURM_COMMANDS:
                    (shadow / entry.name).symlink_to(entry.path)
            folder = str(shadow)
        folders.append(folder)
    return os.pathsep.join(folders)
