"""`python -m bench`: one method x frequency configuration x prior over the captures of a dataset (Hydra app).

Writes `results.csv` (one row per evaluated capture frame) and `depth/<object>_<distance>_<frame>.png` + `.json`
into the run directory (DESIGN.md section 3). Timings exclude file I/O and one-time kernel compilation.
"""
from __future__ import annotations

import logging
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, MissingMandatoryValue, OmegaConf

from bench import maroon
from bench.antennas import load_antenna_array
from bench.errors import DatasetError
from bench.grids import grid_for
from bench.results import write_depth, write_results
from metrics.evaluate import METRIC_COLUMNS, evaluate, ground_truth

log = logging.getLogger("bench")
CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"


def _capture_dirs(dataset: DictConfig, root: Path) -> list[Path]:
    if dataset.captures is None:
        return maroon.discover_captures(root)
    dirs = [root / str(name) for name in dataset.captures]
    for path in dirs:
        if not path.is_dir():
            raise DatasetError(path, "capture listed in dataset.captures does not exist")
    return dirs


def _ensure_synthetic(dataset: DictConfig, root: Path) -> None:
    """Generate (or reuse from cache) the synthetic captures the dataset config asks for."""
    if dataset.generate is None:
        return
    from bench.synth import SynthConfig, generate_catalogue

    objects = None if dataset.generate.objects is None else list(dataset.generate.objects)
    generate_catalogue(root, distances=list(dataset.generate.distances), objects=objects, config=SynthConfig(),
                       log=lambda r: log.info("synthetic %s: %s (%.1f s)", r.path, r.status, r.seconds))


def _parts(prior: str) -> tuple[str, ...]:
    parts = ["radar", "mesh"]
    if prior == "realsense":
        parts.append("realsense")
    return tuple(parts)


def run(cfg: DictConfig, out_dir: Path) -> list[dict]:
    """Evaluate every capture of the configured dataset; returns the result rows (also written to disk)."""
    import methods

    root = Path(to_absolute_path(str(cfg.dataset.root)))
    _ensure_synthetic(cfg.dataset, root)
    targets_ghz = None if cfg.freq.f_ghz is None else [float(f) for f in cfg.freq.f_ghz]
    grid_override = None if cfg.grid.override is None else OmegaConf.to_container(cfg.grid.override)
    params = OmegaConf.to_container(cfg.method.params)
    antenna_files = cfg.dataset.antennas
    antennas = load_antenna_array(*(None if f is None else to_absolute_path(str(f))
                                    for f in (antenna_files.tx_file, antenna_files.rx_file)))
    rows = []
    for capture_dir in _capture_dirs(cfg.dataset, root):
        capture = maroon.read_capture(capture_dir, frame=int(cfg.dataset.frame), parts=_parts(cfg.prior.name),
                                      empty_filtered=bool(cfg.dataset.empty_filtered), antennas=antennas)
        grid = grid_for(capture, grid_override)
        rec = methods.reconstruct(capture, method=cfg.method.name, freq=targets_ghz, prior=cfg.prior.name,
                                  scalar_prior_m=float(cfg.prior.scalar_m), device=cfg.device, grid=grid,
                                  threshold_db=float(cfg.threshold_db), **params)
        stem = f"{capture.object_name}_{capture.distance_cm}_{capture.radar.index:06d}"
        write_depth(out_dir, stem, rec.depth_m, rec.grid)
        if capture.mesh is not None:
            scores = evaluate(rec.depth_m, ground_truth(capture, rec.grid), faithful=bool(cfg.metrics.faithful))
        else:
            scores = dict.fromkeys(METRIC_COLUMNS, float("nan"))
            log.warning("%s: no photogrammetry mesh, metrics left empty", capture.name)
        row = {"object": capture.object_name, "distance": capture.distance_cm, "frame": capture.radar.index,
               "method": cfg.method.name, "freq": cfg.freq.name, "prior": cfg.prior.name,
               "f_GHz": " ".join(f"{f / 1e9:.4f}" for f in rec.freqs_hz), "valid_px": int(rec.valid.sum()),
               "runtime_ms": rec.timings_ms["total"], "device": rec.extra.get("device", cfg.device), **scores}
        row.update({f"t_{stage}_ms": ms for stage, ms in rec.timings_ms.items() if stage != "total"})
        rows.append(row)
        log.info("%s: %d valid pixels, %.1f ms, P %.2f cm, C_s %.2f cm", capture.name, row["valid_px"],
                 row["runtime_ms"], scores["P_cm"], scores["C_s_cm"])
        write_results(out_dir / "results.csv", rows)   # after every capture: an interruption loses no row
    return rows


@hydra.main(version_base="1.3", config_path=str(CONFIG_DIR), config_name="config")
def main(cfg: DictConfig) -> None:
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        run(cfg, out_dir)
    except DatasetError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
    except MissingMandatoryValue as err:
        print(f"error: the setting '{err.full_key}' is required (e.g. {err.full_key}=/path/to/maroon)", file=sys.stderr)
        sys.exit(2)
    except ValueError as err:  # invalid combination of method, frequencies and prior
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
