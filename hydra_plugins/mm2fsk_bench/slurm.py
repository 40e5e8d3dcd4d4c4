"""The SLURM launcher of configs/hydra/launcher/slurm_cpu.yaml and slurm_gpu.yaml; the work is in
bench.harness.slurm.launcher."""
from bench.harness.slurm.launcher import CheckedSlurmLauncher as _CheckedSlurmLauncher


class CheckedSlurmLauncher(_CheckedSlurmLauncher):
    """bench.harness.slurm.launcher.CheckedSlurmLauncher, registered where Hydra looks for plugins."""
