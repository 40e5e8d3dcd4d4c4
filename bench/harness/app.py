"""`python -m bench`: one method x frequency configuration x prior over the captures of a dataset (Hydra app).

Writes `results.csv` (one row per evaluated capture frame), `depth/<object>_<distance>_<frame>.png` + `.json` and
`arrays.h5` (per capture: depth_m, magnitude, gt_depth_m) into the run directory (DESIGN.md section 3). Timings
exclude file I/O and one-time kernel compilation. With `store.dir` set (the default), every cell is looked up in
the result store first (bench.harness.store) and only missing cells are computed. Multiruns (`-m`, e.g.
`+experiment=table3`) merge their rows into the sweep root (bench.report.merge).
"""
from __future__ import annotations

import functools
import hashlib
import inspect
import io
import logging
import os
import socket
import statistics
import tempfile
import time
from concurrent.futures import Future
from pathlib import Path

import h5py
import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, MissingMandatoryValue, OmegaConf

from bench import cli
from bench.cachedir import default_cache_dir
from bench.harness import CONFIG_DIR, captures, sizing, stages, validate, workers
from bench.harness import results as outputs
from bench.harness.durations import Durations, configuration_id
from bench.harness.grids import grid_for
from bench.harness.identity import params_string
from bench.harness.results import BackgroundWriter, ResultsCsv, write_depth
from bench.harness.sizing import contended, machine_load, runs_jobs_here, sweep_jobs, timing_mode
from bench.harness.store import Store, capture_files, code_version, copy_cell, write_arrays
from bench.maroon import reader
from bench.maroon.frames import parse_frame_spec, select_frames
from bench.progress import each
from methods.domain.capture import Capture, RadarGrid
from methods.domain.errors import DatasetError
from methods.ops.frequencies import config_targets_ghz
from metrics.evaluate import SCORE_COLUMNS, GroundTruth

log = logging.getLogger("bench")


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
    cached = []

    def report(result) -> None:       # a generated capture gets its line; those found ready one line in all
        if result.status == "cached":
            cached.append(result)
        else:
            log.info("synthetic %s: %s (%.1f s)", result.path, result.status, result.seconds)

    try:
        generate_catalogue(root, distances=list(dataset.generate.distances), objects=objects, config=config,
                           log=report,
                           on_wait=lambda: log.info("waiting for another process generating captures in %s", root))
    except ForeignRootError:
        log.info("%s holds data the generator did not write: reading it as it is, generating nothing", root)
    if cached:
        log.info("synthetic %s: %d captures up to date (%.1f s)", root, len(cached), sum(r.seconds for r in cached))


def _parts(prior: str) -> tuple[str, ...]:
    """The capture parts a cell's result depends on (its store key covers their files): the radar frame, the mesh
    (ground truth) and the prior's sensor."""
    parts = ["radar", "mesh"]
    if prior == "realsense":
        parts.append("realsense")
    return tuple(parts)


def _method_parts(prior: str) -> tuple[str, ...]:
    """The parts the method reads: the radar frame and its prior's (the mesh is the photogrammetry prior); the
    ground truth's mesh is read only when the ground truth is not kept (bench.harness.captures)."""
    return ("radar", *{"realsense": ("realsense",), "photogrammetry": ("mesh",)}.get(prior, ()))


def _antenna_files(cfg: DictConfig) -> tuple[str | None, str | None]:
    files = cfg.dataset.antennas
    return tuple(None if f is None else to_absolute_path(str(f)) for f in (files.tx_file, files.rx_file))


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


def _check_method(cfg: DictConfig, method) -> None:
    """Refuse a frequency configuration or prior the method does not accept before any data is generated or read,
    naming the configurations (`freq='d10'`, not its frequencies); a configuration of all frequencies (`full`) is
    counted when the frame is read."""
    from methods.api import parse_prior

    n_freqs = len(cfg.freq.f_ghz) if cfg.freq.f_ghz is not None else (method.n_freqs or 0)
    method.check(n_freqs, cfg.freq.name, parse_prior(cfg.prior.name))


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


def _reconstruct(cfg: DictConfig, method, capture: Capture, grid: RadarGrid, device: str):
    """`methods.reconstruct` as configured, timed: (Reconstruction, timing columns). The machine's load
    (`load_1m`, before the call) and the process's CPU time and wall time of the call (`cpu_ms`, `call_ms`) go
    beside the method's own warm runtime. With `timing.repeat` N > 1 the call is repeated while the repeats fit in
    `timing.budget_s` (at most N calls) and `runtime_ms` is the median of their runtimes (`runtime_runs` calls):
    one busy moment of the machine then does not make the figure."""
    import methods

    targets_ghz = None if cfg.freq.f_ghz is None else [float(f) for f in cfg.freq.f_ghz]
    call = functools.partial(methods.reconstruct, capture, method=method, freq=targets_ghz, prior=cfg.prior.name,
                             scalar_prior_m=float(cfg.prior.scalar_m), device=device, grid=grid, roi=_roi(cfg),
                             threshold_db=float(cfg.threshold_db), prior_options=_prior_options(cfg))
    load_1m = machine_load()
    start = sizing.CLOCK.sample()
    cpu_s, wall_s = time.process_time(), time.perf_counter()
    with stages.stage("methods"):
        rec = call()
    columns = {"load_1m": load_1m, "cpu_ms": 1e3 * (time.process_time() - cpu_s),
               "call_ms": 1e3 * (time.perf_counter() - wall_s)}
    runtimes_ms = [rec.timings_ms["total"]]
    budget_ms = 1e3 * float(cfg.timing.budget_s)
    while len(runtimes_ms) < int(cfg.timing.repeat) and sum(runtimes_ms) + runtimes_ms[0] <= budget_ms:
        with stages.stage("methods"):
            runtimes_ms.append(call().timings_ms["total"])
    # what the rest of the machine used over the timed calls, in cores (over a short call's last 0.2 s or more:
    # bench.harness.sizing.CpuClock)
    columns["others_cores"] = sizing.CLOCK.others_cores(start, sizing.CLOCK.sample())
    return rec, {"runtime_ms": statistics.median(runtimes_ms), "runtime_runs": len(runtimes_ms), **columns}


def _compute(cfg: DictConfig, method, capture: Capture, grid: RadarGrid, device: str, gt: GroundTruth | None
             ) -> tuple[dict, workers.Scoring]:
    """Reconstruct on `grid`: (the row's columns without identification, its score columns left empty, and what
    scoring it on the capture's metric grid needs: bench.harness.workers.score)."""
    rec, timing_columns = _reconstruct(cfg, method, capture, grid, device)
    if gt is None:
        log.warning("%s: no photogrammetry mesh, metrics left empty", capture.name)
    row = {"f_GHz": " ".join(f"{f / 1e9:.4f}" for f in rec.freqs_hz), "valid_px": int(rec.valid.sum()),
           **timing_columns, "device": rec.device,
           "compute_grid_size": "x".join(map(str, rec.grid.size)), "roi_px": rec.extra.get("roi_px"),
           **dict.fromkeys(SCORE_COLUMNS)}
    row.update({f"t_{stage}_ms": ms for stage, ms in rec.timings_ms.items() if stage != "total"})
    task = workers.Scoring(rec.depth_m, rec.magnitude, rec.grid, capture.radar.grid, gt,
                           bool(cfg.metrics.faithful), rec.invalid_reason)
    return row, task


@functools.lru_cache(maxsize=4)
def _store(root: str) -> Store:
    """One Store per root and process: the basic launcher's later cells find the capture files' digests in its
    memory (bench.harness.store.Store.file_digest) instead of reading them from the store's disk cache again."""
    return Store(root)


def kept_inputs_dir(cfg: DictConfig) -> Path | None:
    """`store.cache` as a folder (auto: the user's cache folder, bench.cachedir.default_cache_dir), or
    None (null, or auto where no cache folder is known)."""
    setting = OmegaConf.select(cfg, "store.cache", default=None)
    if setting is None:
        return None
    return default_cache_dir() if setting == "auto" else Path(to_absolute_path(str(setting)))


def _kept_inputs(cfg: DictConfig, dataset_root: Path) -> Store | None:
    """Where a run without a result store keeps the ground truths' rasters, the parsed meshes and the files' digests,
    by content (bench.harness.captures): `store.cache`, so that a later process neither imports Open3D nor casts
    rays for captures seen before. None where nothing is kept: `store.cache=null`, or `auto` where the user's cache
    folder cannot be written (nothing kept, the run goes on). A folder inside the dataset is a user error: the
    dataset is never written."""
    folder = kept_inputs_dir(cfg)
    if folder is None:
        return None
    if folder.resolve().is_relative_to(dataset_root.resolve()):
        if cfg.store.cache == "auto":
            return None              # a dataset holding the user's cache folder (e.g. the home): nothing kept
        raise cli.UserError(f"store.cache={cfg.store.cache}", f"is inside the dataset ({dataset_root}), which is "
                                                              "never written: name a folder outside it")
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    if not (existing.is_dir() and os.access(existing, os.W_OK | os.X_OK)):
        return None                 # `auto` only: a named folder was checked by `main` (one line if not writable)
    return _store(str(folder))


def _grid_attrs(grid: RadarGrid) -> dict:
    return {"bb_min_m": list(grid.bb_min_m), "bb_max_m": list(grid.bb_max_m), "grid_size": list(grid.size)}


def _identity(cfg: DictConfig, method, params: str) -> dict:
    """The columns that say which configuration a row is of (with the capture frame's, its identity:
    bench.harness.identity): set on every row, a stored one too (its key holds the values, not the names)."""
    return {"method": method.name, "label": method.label, "freq": cfg.freq.name, "prior": cfg.prior.name,
            "grid": cfg.grid.name, "params": params, "metrics": "faithful" if cfg.metrics.faithful else "sound"}


def _reusable(stored_timing: str | None, timing: str) -> bool:
    """Whether a stored row's runtime serves a run asking for `timing`: any serves 'parallel'; 'alone' takes a
    row timed alone, or one timed under contention while the machine is still busy (re-measuring could not do
    better), never one timed beside other jobs of its sweep."""
    if timing != "alone" or stored_timing == "alone":
        return True
    return stored_timing == "contended" and contended(machine_load())


def _stem(row: dict) -> str:
    return f"{row['object']}_{row['distance']}_{row['frame']:06d}"


def _arrays_attrs(grid: RadarGrid, key: str | None) -> dict:
    """The attributes of a capture's group in arrays.h5."""
    return {**_grid_attrs(grid), "key": key or ""}


def _write_outputs(out_dir: Path, row: dict, arrays: dict | bytes | None, grid: RadarGrid, store: Store | None,
                   key: str | None, results_csv: ResultsCsv, depth_written: bool = False,
                   arrays_written: bool = False) -> None:
    """One capture's files: depth PNG + JSON + preview (unless a worker wrote them), its arrays in arrays.h5 (unless
    the output process wrote them; copied from the store's cell when there is one, or from the image of one a worker
    compressed: `arrays` as bytes), its results.csv line."""
    with stages.stage("outputs"):
        stem = _stem(row)
        if not depth_written:
            write_depth(out_dir, stem, arrays["depth_m"], grid)
        if not arrays_written:
            _add_arrays(out_dir / "arrays.h5", stem, arrays, _arrays_attrs(grid, key), store, key)
        results_csv.add(row)       # appended after every capture: an interruption loses no row


def _add_arrays(path: Path, stem: str, arrays: dict | bytes | None, attrs: dict, store: Store | None,
                key: str | None) -> None:
    """A capture's arrays into arrays.h5 as group `stem` (bench.harness.store.write_arrays' layout)."""
    if store is not None:      # compressed once, into the store
        store.copy_arrays(key, path, stem, attrs)
    elif isinstance(arrays, bytes):
        with h5py.File(io.BytesIO(arrays), "r") as image:
            copy_cell(image, path, stem, attrs)
    else:
        write_arrays(path, stem, arrays, attrs)


def run(cfg: DictConfig, out_dir: Path, *, generate: bool = False, timing: str = "alone", params: str = "",
        defer_outputs: bool = False) -> list[dict]:
    """Evaluate every capture of the configured dataset; returns the result rows (also written to disk).

    The method, its parameters and the prior are checked before any data is generated or read. `generate`: first
    generate missing synthetic captures (the dataset config's `generate` settings; the command line sets it only
    where the user asked for synthetic data, see `synthetic_asked`). `timing` ('alone' or 'parallel', see
    `timing_mode`) goes into every computed row ('contended' instead of 'alone' when the machine was busy,
    bench.harness.sizing.contended); with 'alone' a stored row timed beside other jobs is recomputed, so a
    contended runtime never passes for a clean one. `params`: the row's parameters (bench.harness.identity).
    Output files are written on a background thread while the next capture computes; with `defer_outputs` (a
    basic launcher's sweep: its next job runs in this process) the run returns before the last of them are written
    (bench.harness.results.defer) and its rows are complete once `finish_deferred` returned; the next run waits for
    them first.
    """
    from methods.backends import resolve_device

    with stages.stage("outputs"):
        outputs.finish_deferred()

    device = resolve_device(cfg.device)
    method = _method(cfg)
    _check_method(cfg, method)
    cell = _cell(cfg, device, method)
    root = Path(to_absolute_path(str(cfg.dataset.root)))
    if generate:
        ensure_synthetic(cfg.dataset, root, cfg.synth)
    if not root.exists():
        raise DatasetError(root, "dataset root does not exist")
    store = None if cfg.store.dir is None else _store(to_absolute_path(str(cfg.store.dir)))
    kept = store if store is not None else _kept_inputs(cfg, root)
    grid_override = _container(cfg.grid.override)
    spec = parse_frame_spec(OmegaConf.to_container(cfg.dataset.frame) if OmegaConf.is_list(cfg.dataset.frame)
                            else cfg.dataset.frame)
    empty_filtered, parts = bool(cfg.dataset.empty_filtered), _parts(cfg.prior.name)
    antenna_files = _antenna_files(cfg)
    identity = _identity(cfg, method, params)
    out_dir.mkdir(parents=True, exist_ok=True)
    pool = workers.pool(workers.pool_size(OmegaConf.select(cfg, "evaluation.workers", default=0), device,
                                          shared=timing == "parallel"))
    if pool is not None:
        timing = "parallel"              # the workers share the host with the timed calls (bench.harness.workers)
    writing = pool or workers.output_process(shared=timing == "parallel")     # writes the depth files elsewhere
    # the output process's tasks run one after another, in the order handed: it is the one writer of arrays.h5
    # (a computed capture's arrays as it compresses them, a stored cell's copied there), in capture order
    owns_arrays = pool is None and writing is not None
    rows, results_csv, writer, job_log = [], ResultsCsv(out_dir / "results.csv"), BackgroundWriter(), _JobLog()
    with stages.stage("reading"):
        todo = [(d, f) for d in _capture_dirs(cfg.dataset, root) for f in _frames(d, spec)]
    label = f"{method.label} {cfg.freq.name}{f' {params}' if params else ''}"
    durations = None if store is None else Durations(store.root)
    configuration = configuration_id(cell)
    expected_s = None if durations is None else durations.seconds(configuration)
    computed_s = []
    try:
        # a bar per job only when it runs alone: jobs side by side on one terminal would draw over each other
        for capture_dir, frame in each(todo, label, unit="frame", enabled=timing == "alone", expected_s=expected_s):
            started = time.perf_counter()
            key = hit = None
            if store is not None:
                with stages.stage("reading"):
                    files = capture_files(capture_dir, frame, parts, empty_filtered) + [
                        Path(f) for f in antenna_files if f is not None]
                    key = store.key({**cell, "frame": frame, "capture": store.capture_digest(files)})
                    hit = store.get(key, names=("depth_m",))     # the depth PNG's; arrays.h5 gets copies (below)
                if hit is not None and not _reusable(hit[0].get("timing"), timing):
                    hit = None           # its runtime was measured beside other jobs (or not recorded): re-measure
            if hit is None:
                row, task, grid = _computed_row(cfg, method, capture_dir, frame, empty_filtered, antenna_files,
                                                kept, grid_override, device, timing, identity)
                row.update(hostname=socket.gethostname(), code_version=cell["code"], key=key)
                result = _scored(task, row, grid, out_dir, store, pool, writing, writer, owns_arrays)
                computed_s.append(time.perf_counter() - started)
            else:
                row, arrays, attrs = hit
                row.update(identity)
                grid = RadarGrid(tuple(attrs["bb_min_m"]), tuple(attrs["bb_max_m"]),
                                 tuple(map(int, attrs["grid_size"])))
                result = workers.done((row, arrays, {}))
            if not owns_arrays:
                copied = False
            elif hit is None:
                copied = True          # written by the output process with the capture's other files (`_scored`)
            else:                      # a stored cell's arrays, copied by the output process in capture order
                copied = writing.submit(workers.copy_stored, str(store.root), key, out_dir / "arrays.h5", _stem(row),
                                        _arrays_attrs(grid, key))
            rows.append({"object": row["object"], "distance": row["distance"], "cached": hit is not None})
            writer.submit(_finish, result, rows, len(rows) - 1, out_dir, grid, store, key, results_csv,
                          hit is None and writing is not None, job_log, copied)
    except BaseException:
        with stages.stage("outputs"):
            writer.close()
        raise
    if defer_outputs:
        outputs.defer(writer, out_dir, job_log.close)
    else:
        with stages.stage("outputs"):
            writer.close()
    if durations is not None and computed_s:
        durations.record(configuration, statistics.fmean(computed_s))
    cached = sum(row["cached"] for row in rows)
    if cached:
        log.info("%d of %d capture frames from the store (%s)", cached, len(rows), store.root)
    return rows


def _scored(task: workers.Scoring, row: dict, grid: RadarGrid, out_dir: Path, store: Store | None, pool, writing,
            writer: BackgroundWriter, owns_arrays: bool = False):
    """A computed capture scored (bench.harness.workers): in this thread without a pool, its depth files and cell
    then written by the output process (`writing`, bench.harness.workers.output_process) or, without one, the
    writer; else in a worker, which also writes them. A future of (row, arrays, their image or None, the other
    process's seconds by stage)."""
    if pool is None:
        with stages.stage("metrics"):
            scores, arrays = workers.score(task, row["device"])     # the methods' device (Warp started on CUDA)
        row.update(scores)
        if writing is not None:
            return writing.submit(workers.write, row, arrays, grid, out_dir, _stem(row), _grid_attrs(grid),
                                  None if store is None else str(store.root),
                                  _arrays_attrs(grid, row["key"]) if owns_arrays else None)
        if store is not None:
            writer.submit(store.put, row["key"], row, arrays, _grid_attrs(grid))
        return workers.done((row, arrays, {}))
    task.gt = workers.shipped(task.gt)
    return pool.submit(workers.score_and_write, task, row, out_dir, _stem(row), _grid_attrs(grid),
                       None if store is None else str(store.root))


def _finish(result, rows: list[dict], index: int, out_dir: Path, grid: RadarGrid, store: Store | None,
            key: str | None, results_csv: ResultsCsv, by_worker: bool, job_log,
            arrays_by_worker: bool | Future = False) -> None:
    """On the writer thread, in capture order: the capture's scored row (waiting for its worker, which wrote its
    depth files: `by_worker`, and its arrays into arrays.h5: `arrays_by_worker`, a future where the output process
    copies a stored cell's) as entry `index` of the run's `rows`, and its files (`_write_outputs`)."""
    row, arrays, worker_s = result.result()
    copied_s = arrays_by_worker.result() if isinstance(arrays_by_worker, Future) else {}
    for stage, seconds in [*worker_s.items(), *copied_s.items()]:
        stages.add_background(stage, seconds)
    # one item assignment: a reader of `rows` on another thread sees the placeholder or the whole row, never a half
    cached = rows[index]["cached"]
    entry = {**row, "cached": cached}
    rows[index] = entry
    _write_outputs(out_dir, entry, arrays, grid, store, key, results_csv, depth_written=by_worker,
                   arrays_written=bool(arrays_by_worker))
    if not cached:
        job_log("%s/%s: computed, %d valid pixels, %.1f ms, P %.2f cm, C_s %.2f cm", row["object"], row["distance"],
                row["valid_px"], row["runtime_ms"], row["P_cm"], row["C_s_cm"])


class _JobLog:
    """`log.info` into the handlers logging has now (the job's, which Hydra replaces when the next job starts): for
    lines the writer thread logs after its job returned (`defer_outputs`). `close` closes the job's files again once
    its writer is done: a FileHandler that Hydra closed reopens its file on the next line and would keep it open."""

    def __init__(self):
        self.handlers = [*log.handlers, *(logging.getLogger().handlers if log.propagate else ())]

    def __call__(self, message: str, *args) -> None:
        if log.isEnabledFor(logging.INFO):
            record = log.makeRecord(log.name, logging.INFO, __file__, 0, message, args, None)
            for handler in self.handlers:
                if record.levelno >= handler.level:
                    handler.handle(record)

    def close(self) -> None:
        for handler in self.handlers:
            if isinstance(handler, logging.FileHandler) and handler not in _live_handlers():
                handler.close()


def _live_handlers() -> list[logging.Handler]:
    return [*log.handlers, *logging.getLogger().handlers]


def _computed_row(cfg: DictConfig, method, capture_dir: Path, frame: int, empty_filtered: bool, antenna_files,
                  kept: Store | None, grid_override, device: str, timing: str, identity: dict
                  ) -> tuple[dict, workers.Scoring, RadarGrid]:
    """Read and reconstruct one capture frame: (row with its score columns empty, what scoring it needs, metric
    grid). `kept`: where parsed meshes and ground truths are kept (`_kept_inputs`)."""
    def read(parts):
        with stages.stage("reading"):
            return captures.read(capture_dir, frame, parts, empty_filtered, antenna_files, kept)

    capture = read(_method_parts(cfg.prior.name))
    with stages.stage("ground truth"):
        key = None if kept is None else captures.kept_key(kept, capture_dir, frame, empty_filtered,
                                                          capture.radar.grid, antenna_files)
        gt = captures.ground_truth(capture_dir, capture, lambda: read((*_method_parts(cfg.prior.name), "mesh")),
                                   kept, key)
    grid = capture.radar.grid
    row = {"object": capture.object_name, "distance": capture.distance_cm, "frame": capture.radar.index, **identity,
           "radar_time_s": capture.radar.timestamp_s, **_pairing_columns(capture, capture_dir)}
    columns, task = _compute(cfg, method, capture, grid_for(capture, grid_override), device, gt)
    busy = timing == "alone" and contended(columns["load_1m"], columns.get("others_cores", float("nan")))
    row.update(columns, timing="contended" if busy else timing)
    return row, task, grid


def _next_job_here(hydra_cfg: DictConfig) -> bool:
    """Whether the multirun's next job runs in this process after this one (the in-process and basic launchers):
    this job's last output files may then be written while it starts (the merge callback waits for them)."""
    return hydra_cfg.mode == RunMode.MULTIRUN and runs_jobs_here(hydra_cfg.launcher)


def _isolate_warp_cache() -> None:
    """Parallel jobs must not compile Warp kernels into one cache directory (DESIGN.md 8): one per process for a
    multirun whose jobs run in other processes (joblib, submitit). Jobs run in this process one after another (the
    in-process and basic launchers) use Warp's own cache, as a single run does: kernels compiled by one sweep serve
    the next (a folder per process id made every such sweep compile them anew: ~40 s for Table III on the H100)."""
    hydra_cfg = HydraConfig.get()
    if (hydra_cfg.mode == RunMode.MULTIRUN and not runs_jobs_here(hydra_cfg.launcher)
            and "WARP_CACHE_PATH" not in os.environ):
        os.environ["WARP_CACHE_PATH"] = str(Path(tempfile.gettempdir()) / f"bench-warp-{os.getuid()}-{os.getpid()}")


def progress_line(cfg: DictConfig, hydra_cfg: DictConfig, rows: list[dict], seconds: float, params: str = ""
                  ) -> str:
    """What a finished job prints: `[table3 5/13] bp_d05: 8 captures, 3 computed, 5 cached, 12.3 s` in a multirun
    (job number of the sweep's jobs), `mm2fsk_d10_realsense: 2 captures, ... -> <run dir>` for a single run; the
    job's parameters follow its cell (`custom_d10_realsense offset_mm=2: ...`)."""
    cell = hydra_cfg.runtime.choices.get("cell") or f"{cfg.method.name}_{cfg.freq.name}_{cfg.prior.name}"
    cell += f" {params}" if params else ""
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
        elif OmegaConf.select(cfg, "store.cache", default=None) not in (None, "auto"):
            cli.check_creatable_dir(kept_inputs_dir(cfg), f"store.cache={cfg.store.cache}")
        started = time.perf_counter()
        params = params_string(list(hydra_cfg.overrides.task))
        rows = run(cfg, out_dir, generate=synthetic_asked(list(hydra_cfg.overrides.task)),
                   timing=timing_mode(hydra_cfg), params=params, defer_outputs=_next_job_here(hydra_cfg))
        print(progress_line(cfg, hydra_cfg, rows, time.perf_counter() - started, params), flush=True)
    except BrokenPipeError:    # stdout closed (`... | head`): quiet exit 141, not Hydra's traceback
        cli.exit_on_closed_stdout()
    except MissingMandatoryValue as err:
        cli.fail(f"the setting '{err.full_key}' is required (e.g. {err.full_key}=/path/to/maroon)")
    except Exception as err:   # noqa: BLE001 -- dataset, path, device and file errors in one line; bugs re-raised
        message = cli.error_line(err)
        if message is None:
            raise
        cli.fail(message)
