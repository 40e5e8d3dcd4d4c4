"""Memory a sweep job asks SLURM for, from its cell (`mem_gb: 0` in configs/hydra/launcher/slurm_cpu.yaml).

A model fitted to the peak resident set size of whole jobs (`python -m bench.perf memory`, os.wait4's ru_maxrss)
on the 2-core development machine, on synthetic captures (94 x 94 x 128 radar frames, 301 x 301 metric grid):

    peak_mib = BASE_MIB + min(FRAME_MIB * (frames held - 1), KEPT_CAP_MIB) + BP's larger of
               (voxels * BP_VOXEL_BYTES, RANGE_TABLE_MIB with many frequencies)

* BASE_MIB: the interpreter with numpy, scipy, Open3D, Warp, Hydra and pandas, one capture frame, its ground
  truth and an FSK method's maps (MM-2FSK, 2FSK, 3FSK differ by < 5 %).
* FRAME_MIB: each further capture frame the job keeps, up to KEPT_CAP_MIB: bench.harness.captures keeps frames and
  ground truths in two caches of at most KEPT_MIB of arrays each, so memory stops growing there, whatever
  `dataset.frame=all` or the number of captures selects.
* BP: on its compute grid's voxels (nx * ny * nz) the volume and search buffers; with many frequencies (BP_max)
  the range path holds the pairs' range profiles instead of the dense volume (measured: 442-443 MiB on both the
  paper grid and bp_cpu, two captures), so the larger of the two.

The request is MARGIN times the model, in whole GiB, at least MIN_GB: the margin covers what the synthetic
captures do not have (real MAROON meshes and RealSense frames are larger), allocator fragmentation and other
library versions. GPU jobs (device=cuda) add CUDA_HOST_GB for the CUDA driver's and Warp's host memory (not
measured here: no GPU on the machine the model was fitted on).
"""
from __future__ import annotations

import math

from omegaconf import DictConfig

BASE_MIB = 360.0            # measured 249-269 MiB (one capture), 285-354 MiB (two; 350-354 in a full test run,
                            # unexplained: the base keeps ~10 % above that); 246-251 MiB (two) a day later on the
                            # same machine and commit, the highest figure kept
FRAME_MIB = 35.0            # measured 31-36 MiB per further capture frame
BP_VOXEL_BYTES = 11.5       # measured 11.3 B (BP d05, one capture: 466 MiB on the paper grid, 265 MiB on bp_cpu)
RANGE_TABLE_MIB = 8836 * 2048 * 8 / 2**20   # BP_max's range profiles: pairs x 16 x 128 samples x complex64
KEPT_MIB = 1024             # bench.harness.captures.KEPT_MIB (tests/bench/harness/test_slurm_resources.py)
KEPT_CAP_MIB = 2 * KEPT_MIB  # the two caches full
MARGIN = 1.5
MIN_GB = 1
CUDA_HOST_GB = 2


def _voxels(cfg: DictConfig) -> int:
    """Voxels of BP's compute grid (nx * ny * nz): the grid config's override, else the capture's own 301 x 301
    metric grid with 201 depth samples (the paper's, as MAROON's calibration volume)."""
    override = cfg.grid.get("override") or {}
    nxy, nz = int(override.get("nxy", 301)), int(override.get("nz", 201))
    return nxy * nxy * nz


def _frames_held(cfg: DictConfig, captures: int) -> float:
    """Capture frames the job would keep without the caches' limit: one per capture for a single frame, else
    unbounded (a sequence's frames: the limit decides)."""
    frame = cfg.dataset.get("frame", 0)
    return max(1, captures) if isinstance(frame, int) else float("inf")


def job_peak_mib(cfg: DictConfig, captures: int) -> float:
    """The model's peak resident set size (MiB) of a job running `cfg`'s cell over `captures` captures."""
    peak = BASE_MIB + min(FRAME_MIB * (_frames_held(cfg, captures) - 1), KEPT_CAP_MIB)
    if str(cfg.method.name) == "bp":
        freqs = cfg.freq.f_ghz
        many = freqs is None or len(freqs) > 3
        peak += max(_voxels(cfg) * BP_VOXEL_BYTES / 2**20, RANGE_TABLE_MIB if many else 0.0)
    return peak


def job_mem_gb(cfg: DictConfig, captures: int, setting: int | None = 0) -> int | None:
    """The memory (GiB) to ask for: the launcher's `mem_gb` `setting` where it is a number of GiB; for 0, MARGIN
    x the model, rounded up, at least MIN_GB, plus CUDA_HOST_GB on a GPU; None (null: e.g. with `mem_per_cpu`,
    which SLURM does not take beside a per-node memory) asks for none."""
    if setting is None or int(setting) > 0:
        return None if setting is None else int(setting)
    gb = max(MIN_GB, math.ceil(MARGIN * job_peak_mib(cfg, captures) / 1024))
    return gb + (CUDA_HOST_GB if str(cfg.device) == "cuda" else 0)
