"""Every setting of a composed run configuration checked before any work: one line naming the key, the value and
the allowed range (a `bench.cli.UserError`), never a traceback later or an absurd value silently scored.

`check(cfg)` is called by the app (bench.harness.app.main) once the configuration is composed and by the SLURM
launcher for each job before it is submitted; `LauncherCheck` (a Hydra callback, configs/config.yaml) checks the
launcher's own settings before a multirun starts. The ranges:

* threshold_db: 0 ... FLOAT32_RANGE_DB (a float32 magnitude spans no more; beyond it the filter keeps every pixel).
* prior.scalar_m: above 0 and at most MAX_DEPTH_M (the depth prior of a near-field capture).
* freq.f_ghz: null (every frequency) or distinct, finite, positive GHz; whether each lies inside a frame's band is
  checked against the frame when it is read (methods.ops.frequencies.select_frequencies names the frame's file).
* grid.override: null, or xy_half_m and z_half_m above 0 and at most MAX_HALF_WIDTH_M, whole nxy >= 2 and nz >= 1
  within the grid limits (bench.maroon.limits: BENCH_LIMITS grid_pixels, grid_voxels), and a job whose modelled
  memory (bench.harness.resources) fits this machine's.
* dataset.frame: what bench.maroon.frames accepts; dataset.captures: null or relative <object>/<distance> folders;
  store.cache: auto, null or a folder (outside the dataset: bench.harness.app).
* roi: what methods.skips.settings accepts, its switches true/false and its margins finite (steps above 0).
* profile.prior: sound | faithful; booleans (dataset.empty_filtered, metrics.faithful) true/false.
* evaluation.workers: auto, or a whole number from 0 to 4 x the CPUs (bench.harness.workers).
* joblib's n_jobs: a whole number, not 0, at least -(CPUs) (joblib: -1 = every CPU); the SLURM launchers'
  timeout_min >= 0, cpus_per_task >= 1, mem_gb null or >= 0.
"""
from __future__ import annotations

import dataclasses
import math
import os
from pathlib import PurePosixPath
from typing import NoReturn

import numpy as np
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, ListConfig, OmegaConf

from bench import cli

FLOAT32_RANGE_DB = 20 * math.log10(float(np.finfo(np.float32).max) / float(np.finfo(np.float32).tiny))   # 1529 dB
MAX_DEPTH_M = 10.0
MAX_HALF_WIDTH_M = 1.0          # the QAR50's aperture is 0.3 m wide; MAROON images +-0.15 m at 0.2-0.6 m
PROFILE_PRIORS = ("sound", "faithful")


def _fail(key: str, value, allowed: str) -> NoReturn:
    raise cli.UserError(f"{key}={_show(value)}", f"must be {allowed}")


def _show(value) -> str:
    if isinstance(value, (DictConfig, ListConfig)):
        value = OmegaConf.to_container(value)
    text = str(value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def number(key: str, value, low: float, high: float, *, low_open: bool = False, whole: bool = False) -> float:
    """`value` if it is a finite number (a whole one with `whole`) in [low, high] ((low, high] with `low_open`);
    else a UserError naming `key`, the value and the range."""
    kind = "a whole number" if whole else "a number"
    allowed = f"{kind} {'>' if low_open else '>='} {low:g}" + ("" if high == math.inf else f" and <= {high:g}")
    if not _is_number(value) or not math.isfinite(value) or (whole and value != int(value)):
        _fail(key, value, allowed)
    if value < low or (low_open and value == low) or value > high:
        _fail(key, value, allowed)
    return int(value) if whole else float(value)


def boolean(key: str, value) -> None:
    if not isinstance(value, bool):
        _fail(key, value, "true or false")


def _frequencies(cfg: DictConfig) -> None:
    f_ghz = cfg.freq.f_ghz
    if f_ghz is None:
        return
    if not isinstance(f_ghz, (list, ListConfig)) or len(f_ghz) == 0:      # the freq_ghz resolver gives a list
        _fail("freq.f_ghz", f_ghz, "null (every frequency) or a list of frequencies in GHz")
    values = [number("freq.f_ghz", f, 0.0, math.inf, low_open=True) for f in f_ghz]
    if len(set(values)) != len(values):
        _fail("freq.f_ghz", f_ghz, "distinct frequencies")


def _grid(cfg: DictConfig) -> None:
    from bench.maroon.limits import current_limits

    override = OmegaConf.select(cfg, "grid.override", default=None)
    if override is None:
        return
    if not isinstance(override, DictConfig) or set(override) != {"xy_half_m", "nxy", "z_half_m", "nz"}:
        _fail("grid.override", override, "null or {xy_half_m, nxy, z_half_m, nz}")
    limits = current_limits()
    for key in ("xy_half_m", "z_half_m"):
        number(f"grid.override.{key}", override[key], 0.0, MAX_HALF_WIDTH_M, low_open=True)
    nxy = number("grid.override.nxy", override.nxy, 2, math.isqrt(limits.grid_pixels), whole=True)
    number("grid.override.nz", override.nz, 1, max(1, limits.grid_voxels // (nxy * nxy)), whole=True)


def _memory(cfg: DictConfig) -> None:
    """The job's modelled peak memory (bench.harness.resources) against this machine's."""
    from bench.harness.resources import job_peak_mib

    try:
        total_mib = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
    except (ValueError, OSError):        # not known here
        return
    need_mib = job_peak_mib(cfg, captures=1)
    if need_mib > total_mib:
        grid = cfg.grid.get("override") or {"nxy": "301", "nz": "201"}      # the model's default grid
        raise cli.UserError(f"grid={cfg.grid.name}", f"{cfg.method.name} on its {grid['nxy']} x {grid['nxy']} x "
                                                     f"{grid['nz']} grid needs about {need_mib / 1024:.1f} GiB "
                                                     "(bench.harness.resources), this machine has "
                                                     f"{total_mib / 1024:.1f} GiB: use a smaller grid")


def _dataset(cfg: DictConfig) -> None:
    from bench.maroon.frames import parse_frame_spec

    frame = cfg.dataset.frame
    try:
        parse_frame_spec(OmegaConf.to_container(frame) if isinstance(frame, ListConfig) else frame)
    except ValueError:
        _fail("dataset.frame", frame, "an integer (-1 = the last frame), 'all', a range like 0:10 or a list like "
                                      "[0,3,5]")
    captures = cfg.dataset.captures
    if captures is not None:
        if not isinstance(captures, ListConfig):
            _fail("dataset.captures", captures, "null (every capture) or a list like [01_plate/30, 03_sphere/30]")
        for name in captures:
            path = PurePosixPath(str(name))
            if not isinstance(name, (str, int)) or path.is_absolute() or ".." in path.parts or not path.parts:
                _fail("dataset.captures", name, "a folder <object>/<distance> relative to dataset.root")
    boolean("dataset.empty_filtered", cfg.dataset.empty_filtered)
    cache = OmegaConf.select(cfg, "store.cache", default=None)
    if cache is not None and (not isinstance(cache, str) or not cache.strip()):
        _fail("store.cache", cache, "auto, null or a folder")


def _roi(cfg: DictConfig) -> None:
    from methods.skips.settings import SkipSettings, resolve

    node = OmegaConf.select(cfg, "roi", default=None)
    if node is None:
        return
    settings = OmegaConf.to_container(node) if isinstance(node, DictConfig) else node
    try:
        resolve(settings)
    except (ValueError, TypeError) as err:
        raise cli.UserError(f"roi={_show(settings)}", str(err)) from None
    if not isinstance(settings, dict):
        return
    for field in dataclasses.fields(SkipSettings):
        if field.name not in settings:
            continue
        key, value = f"roi.{field.name}", settings[field.name]
        if isinstance(field.default, bool):
            boolean(key, value)
        else:
            number(key, value, 0.0, math.inf, low_open=field.name.endswith("step_m"))


def check(cfg: DictConfig, memory: bool = True) -> None:
    """Every setting of the run configuration `cfg` in its range (module doc), else a UserError (one line).
    `memory`: also the job's modelled memory against this machine's (off where the job runs elsewhere)."""
    number("threshold_db", cfg.threshold_db, 0.0, FLOAT32_RANGE_DB)
    number("prior.scalar_m", cfg.prior.scalar_m, 0.0, MAX_DEPTH_M, low_open=True)
    _frequencies(cfg)
    _grid(cfg)
    _dataset(cfg)
    _roi(cfg)
    if cfg.profile.prior not in PROFILE_PRIORS:
        _fail("profile.prior", cfg.profile.prior, " or ".join(PROFILE_PRIORS))
    boolean("metrics.faithful", cfg.metrics.faithful)
    workers = OmegaConf.select(cfg, "evaluation.workers", default=0)
    if workers != "auto":
        number("evaluation.workers", workers, 0, 4 * (os.cpu_count() or 1), whole=True)
    if memory:
        _memory(cfg)


def check_launcher(launcher: DictConfig) -> None:
    """The launcher's settings (module doc) by its `_target_`: joblib's n_jobs, SLURM's sizes."""
    target = str(launcher.get("_target_", ""))
    if target.endswith("JoblibLauncher"):
        cpus = os.cpu_count() or 1
        n_jobs = number("hydra.launcher.n_jobs", launcher.n_jobs, -cpus, math.inf, whole=True)
        if n_jobs == 0:
            _fail("hydra.launcher.n_jobs", 0, f"a whole number >= 1, or -1 (every CPU) ... -{cpus} (one worker)")
    elif target.endswith("SlurmLauncher"):
        number("hydra.launcher.timeout_min", launcher.timeout_min, 0, math.inf, whole=True)
        number("hydra.launcher.cpus_per_task", launcher.cpus_per_task, 1, math.inf, whole=True)
        if launcher.get("mem_gb") is not None:
            number("hydra.launcher.mem_gb", launcher.mem_gb, 0, math.inf, whole=True)


class LauncherCheck(Callback):
    """Before a multirun's jobs are launched: the launcher's settings (`check_launcher`), one line and exit 2."""

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        try:
            check_launcher(config.hydra.launcher)
        except cli.UserError as err:
            cli.fail(str(err))
