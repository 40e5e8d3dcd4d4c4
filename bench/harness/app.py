"""`python -m bench`: one method x frequency configuration x prior over the captures of a dataset (Hydra app).

Writes `results.csv` (one row per evaluated capture frame), `depth/<object>_<distance>_<frame>.png` + `.json` and
`arrays.h5` (per capture: depth_m, magnitude, gt_depth_m) into the run directory (DESIGN.md section 3). Timings
exclude file I/O and one-time kernel compilation. With `store.dir` set (the default), every cell is looked up in
the result store first (bench.harness.store) and only missing cells are computed. Multiruns (`-m`, e.g.
`+experiment=table3`) merge their rows into the sweep root (bench.report.merge).
"""
from __future__ import annotations

import collections
import dataclasses
import functools
import hashlib
import inspect
import logging
import os
import socket
import tempfile
import time
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, MissingMandatoryValue, OmegaConf

from bench import cli
from bench.harness import validate
from bench.harness.grids import grid_for
from bench.harness.results import ResultsCsv, write_depth
from bench.harness.sizing import sweep_jobs, timing_mode
from bench.harness.store import Store, capture_files, code_version, write_arrays
from bench.maroon import reader
from bench.maroon.antennas import load_antenna_array
from bench.maroon.frames import parse_frame_spec, select_frames
from bench.progress import each
from methods.domain.capture import Capture, RadarGrid
from methods.domain.errors import DatasetError
from methods.ops.frequencies import config_targets_ghz
from metrics.evaluate import GroundTruth, evaluate, ground_truth, no_ground_truth_scores
from metrics.resample import resample_depth_m, resample_nearest

log = logging.getLogger("bench")
CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"


def _freq_ghz(name: str) -> list[float] | None:
    """configs/freq/*.yaml's `f_ghz`: the targets of the one frequency table (methods.ops.frequencies)."""
    targets = config_targets_ghz(name)
    return None if targets is None else list(targets)


OmegaConf.register_new_resolver("freq_ghz", _freq_ghz, replace=True)


def _capture_dirs(dataset: DictConfig, root: Path) -> list[Path]:
    if dataset.captures is None:
        return reader.discover_captures(root)
    dirs = [root / str(name) for name in dataset.captures]
    for path in dirs:
        if not path.is_dir():
            raise DatasetError(path, "capture listed in dataset.captures does not exist")
    return dirs


def synthetic_asked(task_overrides: list[str]) -> bool:
    """Whether the command line asks for synthetic data: `dataset=synthetic` named, or no `dataset.root` given
    (the default root of the default dataset, configs/dataset/synthetic.yaml). Elsewhere nothing is generated."""
    names = [override.lstrip("+~") for override in task_overrides]
    return "dataset=synthetic" in names or not any(name.startswith("dataset.root=") for name in names)


def ensure_synthetic(dataset: DictConfig, root: Path, synth: DictConfig) -> None:
    """Generate (or reuse from cache) the synthetic captures the dataset config asks for (bench.synth).

    Only into a missing or empty folder or one the generator made (it holds its manifest), under the root's lock
    (parallel jobs wait for the first one): a folder with other data, e.g. the real dataset given as
    `dataset.root`, is never written.
    """
    if dataset.generate is None:
        return
    from bench.synth import generate_catalogue
    from bench.synth.config import preset
    from bench.synth.ownership import ForeignRootError

    try:   # the preset and its overrides (configs/synth/): an unknown name or field is a user error
        config = preset(synth.preset, **OmegaConf.to_container(synth.overrides))
        config.validate()
    except (TypeError, ValueError) as err:
        raise cli.UserError("synth", str(err)) from None
    objects = None if dataset.generate.objects is None else list(dataset.generate.objects)
    try:
        generate_catalogue(root, distances=list(dataset.generate.distances), objects=objects, config=config,
                           log=lambda r: log.info("synthetic %s: %s (%.1f s)", r.path, r.status, r.seconds),
                           on_wait=lambda: log.info("waiting for another process generating captures in %s", root))
    except ForeignRootError:
        log.info("%s holds data the generator did not write: reading it as it is, generating nothing", root)


def _parts(prior: str) -> tuple[str, ...]:
    parts = ["radar", "mesh"]
    if prior == "realsense":
        parts.append("realsense")
    return tuple(parts)


def _antenna_files(cfg: DictConfig) -> tuple[str | None, str | None]:
    files = cfg.dataset.antennas
    return tuple(None if f is None else to_absolute_path(str(f)) for f in (files.tx_file, files.rx_file))


_CAPTURES: collections.OrderedDict = collections.OrderedDict()   # (frame key) -> (Capture, parts read)
CAPTURES_KEPT = 16


def _read_capture(capture_dir: Path, frame: int, parts: tuple[str, ...], empty_filtered: bool,
                  antenna_files: tuple[str | None, str | None]) -> Capture:
    """The capture frame with `parts`, each part read once per process: a worker (or the basic launcher's one
    process) runs many cells on the same captures, BP needing radar and mesh and MM-2FSK the RealSense frame too,
    so a later cell reads only the parts no earlier cell read (the RealSense frame paired with the cached radar
    frame's time, as read_capture pairs it)."""
    key = (capture_dir, frame, empty_filtered, antenna_files)
    cached, have = _CAPTURES.pop(key, (None, ()))
    missing = tuple(part for part in parts if part not in have)
    if missing:
        paired = None
        if "realsense" in missing and cached is not None and cached.radar is not None \
                and (capture_dir / "realsense").is_dir():
            paired = reader.realsense_pairing(capture_dir / "realsense", cached.radar.timestamp_s).realsense_frame
        new = reader.read_capture(capture_dir, frame=frame, parts=missing, empty_filtered=empty_filtered,
                                  antennas=load_antenna_array(*antenna_files), realsense_frame=paired)
        if cached is not None:
            new = dataclasses.replace(cached, notes=cached.notes + new.notes,
                                      transforms=new.transforms if "mesh" in missing else cached.transforms,
                                      **{part: getattr(new, part) for part in missing})
        cached, have = new, have + missing
    _CAPTURES[key] = (cached, have)
    while len(_CAPTURES) > CAPTURES_KEPT:
        _CAPTURES.popitem(last=False)
    return dataclasses.replace(cached, **{part: None for part in reader.PARTS if part not in parts})


def _frames(capture_dir: Path, spec) -> list[int]:
    """The radar frame indices `dataset.frame` selects in this capture (bench.maroon.frames)."""
    radar_dir = reader.find_radar_folder(capture_dir)
    return select_frames(reader.list_radar_frames(radar_dir), spec, radar_dir / "calibrated_data")


def _pairing_columns(capture: Capture, capture_dir: Path) -> dict:
    """The RealSense frame paired with the radar frame and its time offset (ms), for a RealSense prior's row."""
    if capture.realsense is None:
        return {}
    pairing = reader.realsense_pairing(capture_dir / "realsense", capture.radar.timestamp_s)
    return {"realsense_frame": capture.realsense.index, "pairing": pairing.rule,
            "realsense_offset_ms": pairing.offset_s * 1e3}


def _container(node):
    """A config node as plain Python (a resolver's value, e.g. freq.f_ghz, is plain already)."""
    return OmegaConf.to_container(node) if OmegaConf.is_config(node) else node


def _roi(cfg: DictConfig) -> str | dict:
    """The cell's skips and region of interest (configs/roi/, methods.skips.settings): the `roi` group's settings, or
    the
    methods' default ('auto') where the config has no `roi` group."""
    node = OmegaConf.select(cfg, "roi", default=None)
    return "auto" if node is None else OmegaConf.to_container(node)


def _method(cfg: DictConfig):
    """The configured method (methods.method.Method) from its `_target_` class and `params`; a path that cannot
    be imported or a class that breaks the interface is a user error of one line."""
    from methods.method import MethodError
    from methods.registry import make_method

    try:
        target = str(cfg.method._target_)
    except MissingMandatoryValue:
        raise cli.UserError("method._target_", "give the method's class, e.g. "
                                               "method._target_=mypkg.mymethod.MyMethod") from None
    try:
        return make_method(target, {**_profile_params(cfg, target), **OmegaConf.to_container(cfg.method.params)})
    except MethodError as err:
        raise cli.UserError(f"method._target_={target}", str(err)) from None


def _profile_params(cfg: DictConfig, target: str) -> dict:
    """The profile's method settings (configs/profile/) for a method that declares them: the 2FSK/MM-2FSK
    filter quantity; `method.params` given on the command line win."""
    from methods.registry import method_class

    declared = method_class(target).params
    return {"filter_quantity": str(cfg.profile.filter)} if "filter_quantity" in declared else {}


def _prior_options(cfg: DictConfig) -> dict:
    """How a sensor prior is built (methods.api.prior_image_m): the profile's construction and, for the RealSense,
    the depth-jump rule `prior.max_jump_mm` (null = off; the default where the prior config does not set it), and
    for a sensor prior the hole fill `prior.fill` (delaunay | scanline; methods.prior.priors)."""
    from methods.prior.priors import DEFAULT_FILL, DEFAULT_MAX_JUMP_MM, FILLS

    options = {"faithful": cfg.profile.prior == "faithful"}
    if cfg.prior.name in ("realsense", "photogrammetry"):
        fill = OmegaConf.select(cfg, "prior.fill", default=DEFAULT_FILL)
        if fill not in FILLS:
            raise cli.UserError(f"prior.fill={fill}", f"must be one of {', '.join(FILLS)}")
        options["fill"] = fill
    if cfg.prior.name == "realsense":
        value = OmegaConf.select(cfg, "prior.max_jump_mm", default=DEFAULT_MAX_JUMP_MM)
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float)) or value <= 0):
            raise cli.UserError(f"prior.max_jump_mm={value}", "must be a positive number of millimetres or null")
        options["max_jump_mm"] = None if value is None else float(value)
    return options


def _method_source(method) -> str | None:
    """sha256 of the file of a method outside the `methods` package (whose sources `code_version` covers)."""
    cls = type(method)
    if cls.__module__.split(".")[0] == "methods":
        return None
    return hashlib.sha256(Path(inspect.getfile(cls)).read_bytes()).hexdigest()


def _cell(cfg: DictConfig, device: str, method) -> dict:
    """Everything but the capture that determines a cell's result (the store key's configuration part)."""
    return {"method": method.name, "target": str(cfg.method._target_), "method_source": _method_source(method),
            "params": OmegaConf.to_container(cfg.method.params), "roi": _roi(cfg),
            "f_ghz": _container(cfg.freq.f_ghz), "prior": cfg.prior.name,
            "scalar_prior_m": float(cfg.prior.scalar_m), "grid": _container(cfg.grid.override),
            "threshold_db": float(cfg.threshold_db),
            "empty_filtered": bool(cfg.dataset.empty_filtered), "faithful": bool(cfg.metrics.faithful),
            "profile": _container(cfg.profile), "prior_options": _prior_options(cfg),
            "device": device, "code": code_version()}


_GROUND_TRUTHS: collections.OrderedDict = collections.OrderedDict()
GROUND_TRUTHS_KEPT = 16


def _ground_truth(capture_dir: Path, capture: Capture) -> GroundTruth:
    """The capture's ground truth on its metric grid (the frame's calibration grid), whatever the cell's prior.

    One ray cast, silhouette and KD-tree per capture, grid and object pose for every cell and frame of a process
    (the basic launcher runs a sweep's jobs in one process): a static object's frames share it."""
    pose = capture.transforms.get("photogrammetry2radar")
    key = (capture_dir, capture.radar.grid, None if pose is None else pose.tobytes())
    if key not in _GROUND_TRUTHS:
        _GROUND_TRUTHS[key] = ground_truth(capture, capture.radar.grid)
        while len(_GROUND_TRUTHS) > GROUND_TRUTHS_KEPT:
            _GROUND_TRUTHS.popitem(last=False)
    _GROUND_TRUTHS.move_to_end(key)
    return _GROUND_TRUTHS[key]


def _compute(cfg: DictConfig, method, capture: Capture, grid: RadarGrid, device: str, gt: GroundTruth | None
             ) -> tuple[dict, dict]:
    """Reconstruct on `grid`, then evaluate on the capture's metric grid (the ground truth's; the depth map is
    resampled there when the method computed on another grid): (row without identification columns, arrays on
    the metric grid)."""
    import methods

    targets_ghz = None if cfg.freq.f_ghz is None else [float(f) for f in cfg.freq.f_ghz]
    rec = methods.reconstruct(capture, method=method, freq=targets_ghz, prior=cfg.prior.name,
                              scalar_prior_m=float(cfg.prior.scalar_m), device=device, grid=grid, roi=_roi(cfg),
                              threshold_db=float(cfg.threshold_db), prior_options=_prior_options(cfg))
    metric_grid = capture.radar.grid
    depth_m = resample_depth_m(rec.depth_m, rec.grid, metric_grid)
    if gt is not None:
        scores, gt_depth_m = evaluate(depth_m, gt, faithful=bool(cfg.metrics.faithful)), gt.depth_m
    else:
        scores, gt_depth_m = no_ground_truth_scores("no photogrammetry mesh"), depth_m * float("nan")
        log.warning("%s: no photogrammetry mesh, metrics left empty", capture.name)
    if rec.invalid_reason:       # the method's own account of an all-invalid result, not just 'no valid'
        scores["failure"] = rec.invalid_reason
    row = {"f_GHz": " ".join(f"{f / 1e9:.4f}" for f in rec.freqs_hz), "valid_px": int(rec.valid.sum()),
           "runtime_ms": rec.timings_ms["total"], "device": rec.device,
           "compute_grid_size": "x".join(map(str, rec.grid.size)), "roi_px": rec.extra.get("roi_px"), **scores}
    row.update({f"t_{stage}_ms": ms for stage, ms in rec.timings_ms.items() if stage != "total"})
    arrays = {"depth_m": depth_m, "magnitude": resample_nearest(rec.magnitude, rec.grid, metric_grid),
              "gt_depth_m": gt_depth_m}
    return row, arrays


@functools.lru_cache(maxsize=4)
def _store(root: str) -> Store:
    """One Store per root and process: the basic launcher's later cells find the capture files' digests in its
    memory (bench.harness.store.Store.file_digest) instead of reading them from the store's disk cache again."""
    return Store(root)


def _grid_attrs(grid: RadarGrid) -> dict:
    return {"bb_min_m": list(grid.bb_min_m), "bb_max_m": list(grid.bb_max_m), "grid_size": list(grid.size)}


def run(cfg: DictConfig, out_dir: Path, *, generate: bool = False, timing: str = "alone") -> list[dict]:
    """Evaluate every capture of the configured dataset; returns the result rows (also written to disk).

    `generate`: first generate missing synthetic captures (the dataset config's `generate` settings; the command
    line sets it only where the user asked for synthetic data, see `synthetic_asked`). `timing` ('alone' or
    'parallel', see `timing_mode`) goes into every computed row; with 'alone' a stored row whose runtime was not
    measured alone is recomputed, so a contended runtime never passes for a clean one.
    """
    from methods.backends import resolve_device

    root = Path(to_absolute_path(str(cfg.dataset.root)))
    if generate:
        ensure_synthetic(cfg.dataset, root, cfg.synth)
    if not root.exists():
        raise DatasetError(root, "dataset root does not exist")
    store = None if cfg.store.dir is None else _store(to_absolute_path(str(cfg.store.dir)))
    device = resolve_device(cfg.device)
    method = _method(cfg)
    cell = _cell(cfg, device, method)
    grid_override = _container(cfg.grid.override)
    spec = parse_frame_spec(OmegaConf.to_container(cfg.dataset.frame) if OmegaConf.is_list(cfg.dataset.frame)
                            else cfg.dataset.frame)
    empty_filtered, parts = bool(cfg.dataset.empty_filtered), _parts(cfg.prior.name)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows, results_csv = [], ResultsCsv(out_dir / "results.csv")
    todo = [(d, f) for d in _capture_dirs(cfg.dataset, root) for f in _frames(d, spec)]
    # a bar per job only when it runs alone: jobs side by side on one terminal would draw over each other
    for capture_dir, frame in each(todo, f"{method.label} {cfg.freq.name}", unit="frame", enabled=timing == "alone"):
        key = hit = None
        if store is not None:
            files = capture_files(capture_dir, frame, parts, empty_filtered) + [Path(f) for f in _antenna_files(cfg)
                                                                                if f is not None]
            key = store.key({**cell, "frame": frame, "capture": store.capture_digest(files)})
            hit = store.get(key, names=("depth_m",))     # the depth PNG's; arrays.h5 gets copies (below)
            if hit is not None and timing == "alone" and hit[0].get("timing") != "alone":
                hit = None           # its runtime was measured beside other jobs (or not recorded): re-measure
        if hit is None:
            capture = _read_capture(capture_dir, frame, parts, empty_filtered, _antenna_files(cfg))
            gt = None if capture.mesh is None else _ground_truth(capture_dir, capture)
            grid = capture.radar.grid
            row = {"object": capture.object_name, "distance": capture.distance_cm, "frame": capture.radar.index,
                   "method": method.name, "label": method.label, "freq": cfg.freq.name, "prior": cfg.prior.name,
                   "grid": cfg.grid.name,
                   "metrics": "faithful" if cfg.metrics.faithful else "sound",
                   "radar_time_s": capture.radar.timestamp_s, **_pairing_columns(capture, capture_dir)}
            scores, arrays = _compute(cfg, method, capture, grid_for(capture, grid_override), device, gt)
            row.update(scores, timing=timing, hostname=socket.gethostname(), code_version=cell["code"], key=key)
            if store is not None:
                store.put(key, row, arrays, _grid_attrs(grid))
        else:
            row, arrays, attrs = hit
            grid = RadarGrid(tuple(attrs["bb_min_m"]), tuple(attrs["bb_max_m"]), tuple(map(int, attrs["grid_size"])))
        stem = f"{row['object']}_{row['distance']}_{row['frame']:06d}"
        write_depth(out_dir, stem, arrays["depth_m"], grid)
        array_attrs = {**_grid_attrs(grid), "key": key or ""}
        if store is not None:      # compressed once, into the store
            store.copy_arrays(key, out_dir / "arrays.h5", stem, array_attrs)
        else:
            write_arrays(out_dir / "arrays.h5", stem, arrays, array_attrs)
        rows.append({**row, "cached": hit is not None})
        results_csv.add(rows[-1])     # appended after every capture: an interruption loses no row
        log.info("%s/%s: %s, %d valid pixels, %.1f ms, P %.2f cm, C_s %.2f cm", row["object"], row["distance"],
                 "cached" if hit else "computed", row["valid_px"], row["runtime_ms"], row["P_cm"], row["C_s_cm"])
    return rows


def _isolate_warp_cache() -> None:
    """Parallel jobs must not compile Warp kernels into one cache directory (DESIGN.md 8): one per process."""
    if HydraConfig.get().mode == RunMode.MULTIRUN and "WARP_CACHE_PATH" not in os.environ:
        os.environ["WARP_CACHE_PATH"] = str(Path(tempfile.gettempdir()) / f"bench-warp-{os.getuid()}-{os.getpid()}")


def progress_line(cfg: DictConfig, hydra_cfg: DictConfig, rows: list[dict], seconds: float) -> str:
    """What a finished job prints: `[table3 5/13] bp_d05: 8 captures, 3 computed, 5 cached, 12.3 s` in a multirun
    (job number of the sweep's jobs), `mm2fsk_d10_realsense: 2 captures, ... -> <run dir>` for a single run."""
    cell = hydra_cfg.runtime.choices.get("cell") or f"{cfg.method.name}_{cfg.freq.name}_{cfg.prior.name}"
    cached = sum(bool(row["cached"]) for row in rows)
    n_captures = len({(row["object"], row["distance"]) for row in rows})
    captures = f"{n_captures} capture{'s' if n_captures != 1 else ''}"
    if len(rows) != n_captures:                  # frame sequences: one row per frame
        captures += f" ({len(rows)} frames)"
    text = f"{cell}: {captures}, {len(rows) - cached} computed, {cached} cached, {seconds:.1f} s"
    if hydra_cfg.mode != RunMode.MULTIRUN:
        return f"{text} -> {hydra_cfg.runtime.output_dir}"
    experiment = hydra_cfg.runtime.choices.get("experiment") or "sweep"
    return f"[{experiment} {hydra_cfg.job.num + 1}/{sweep_jobs() or '?'}] {text}"


@hydra.main(version_base="1.3", config_path=str(CONFIG_DIR), config_name="config")
def main(cfg: DictConfig) -> None:
    hydra_cfg = HydraConfig.get()
    out_dir = Path(hydra_cfg.runtime.output_dir)
    _isolate_warp_cache()
    try:
        cli.resolve_device(str(cfg.device), option="device=")   # before generating or reading anything
        validate.check(cfg)                                       # every setting in its range (one line if not)
        if cfg.store.dir is not None:
            cli.check_creatable_dir(to_absolute_path(str(cfg.store.dir)), f"store.dir={cfg.store.dir}")
        started = time.perf_counter()
        rows = run(cfg, out_dir, generate=synthetic_asked(list(hydra_cfg.overrides.task)),
                   timing=timing_mode(hydra_cfg))
        print(progress_line(cfg, hydra_cfg, rows, time.perf_counter() - started), flush=True)
    except BrokenPipeError:    # stdout closed (`... | head`): quiet exit 141, not Hydra's traceback
        cli.exit_on_closed_stdout()
    except MissingMandatoryValue as err:
        cli.fail(f"the setting '{err.full_key}' is required (e.g. {err.full_key}=/path/to/maroon)")
    except Exception as err:   # noqa: BLE001 -- dataset, path, device and file errors in one line; bugs re-raised
        message = cli.error_line(err)
        if message is None:
            raise
        cli.fail(message)
