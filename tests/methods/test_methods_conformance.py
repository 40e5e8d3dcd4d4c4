"""Every registered method (the built-ins and the worked example) honours the method interface
(methods/method.py) on a tiny capture on each available device, agrees with itself across devices, and the
harness finds a method of one's own by its class path (Hydra's `_target_`), with one-line errors otherwise.

The float64 reference of every fast path is the correlation's (tests/methods/test_correlate.py); the methods were moved
onto the interface with bit-identical depth maps (checked against the commit before the move on synthetic
captures: cpu and warp-cpu, every method, roi=auto and none)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from bench.synth.memory import (
    TABLE1_FREQS_HZ,
    make_capture,
    plane_depth_frame,
    plate_points_m,
    realsense2radar,
    simulate,
    square_grid,
)
from methods import Method, reconstruct
from methods.method import MethodError
from methods.registry import BUILTIN, make_method, method_class

from devices import CUDA

GRID = square_grid(0.003, 7, 0.29, 0.31, 11)            # 7 x 7 pixels of 1 mm; BP: 11 depths of 2 mm
SLOPE_X = 0.05                                          # plate z = 0.30 + 0.05 x
REGISTERED = [*BUILTIN, "examples.prior_only.PriorOnly"]
DEVICES = ["cpu", "warp-cpu", CUDA]


@pytest.fixture(scope="module")
def tilted_plate():
    points_m = plate_points_m(0.30, half_size_m=0.02)
    points_m[:, 2] += SLOPE_X * points_m[:, 0]
    cam2radar = realsense2radar()
    return make_capture(simulate(points_m, np.ones(len(points_m)), TABLE1_FREQS_HZ), TABLE1_FREQS_HZ, GRID,
                        realsense=plane_depth_frame(0.30, SLOPE_X, 0.0, cam2radar),
                        transforms={"realsense2radar": cam2radar})


def _cell(cls: type[Method]) -> tuple[str, str | float]:
    """A frequency configuration and a prior the method accepts: every frequency for a method of any number
    (BP_max: two-frequency BP is ambiguous every 1.5 cm at d10), no prior, else a per-pixel one, else a scalar
    2 mm off the plate."""
    freq = {2: "d10", 3: "d05_d10", None: "full"}[cls.n_freqs]
    if "none" in cls.priors:
        return freq, "none"
    return freq, "realsense" if "realsense" in cls.priors else 0.302


_results: dict = {}


def _run(capture, spec: str, device: str):
    if (spec, device) not in _results:
        freq, prior = _cell(method_class(spec))
        _results[spec, device] = reconstruct(capture, spec, freq, prior=prior, device=device, grid=GRID)
    return _results[spec, device]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("spec", REGISTERED)
def test_every_method_honours_the_interface_on_every_device(tilted_plate, spec, device):
    cls = method_class(spec)
    rec = _run(tilted_plate, spec, device)
    assert rec.method == cls.name and rec.device == device and rec.invalid_reason is None
    assert rec.depth_m.shape == rec.magnitude.shape == GRID.image_shape and rec.grid == GRID
    assert len(rec.freqs_hz) == (cls.n_freqs or len(TABLE1_FREQS_HZ)) and rec.timings_ms["total"] > 0
    x_m, _ = GRID.pixel_xy_m()
    error_m = np.abs(rec.depth_m - (0.30 + SLOPE_X * x_m))[rec.valid]
    assert rec.valid.sum() >= 0.5 * rec.valid.size and error_m.max() < 3e-3     # BP: 2 mm depth steps
    if device != "cpu":                                 # the same result as the numpy backend's
        cpu = _run(tilted_plate, spec, "cpu")
        assert (rec.valid ^ cpu.valid).sum() <= 1       # a pixel at the -14 dB threshold may flip
        both = rec.valid & cpu.valid
        assert np.max(np.abs(rec.depth_m[both] - cpu.depth_m[both])) < 1e-4   # fp16 tensor cores: ~1e-5 m


def test_configs_name_every_builtin_by_its_class():
    from omegaconf import OmegaConf

    from bench.harness.app import CONFIG_DIR
    for name, path in BUILTIN.items():
        cfg = OmegaConf.load(CONFIG_DIR / "method" / f"{name}.yaml")
        assert cfg._target_ == path and method_class(cfg._target_).name == cfg.name == name


class _NoRun(Method):
    name, label, priors = "norun", "No run", ("none",)


class _BadPriors(Method):
    name, label, priors = "badpriors", "Bad priors", ("lidar",)

    def run(self, frame, prior, backend, timer):
        raise AssertionError("never reached")


@pytest.mark.parametrize("spec, message", [
    ("sar", "unknown method 'sar'"),
    ("nowhere.Mine", "method 'nowhere.Mine' cannot be imported: No module named 'nowhere'"),
    ("methods.fsk.Nope", "module methods.fsk has no 'Nope'"),
    ("methods.fsk.depth_correction_m", "is not a methods.method.Method subclass"),
    (_NoRun, "must implement run(frame, prior, backend, timer)"),
    (_BadPriors, ".priors must name some of none, scalar, realsense, photogrammetry"),
])
def test_a_method_that_cannot_be_used_is_one_clear_error(spec, message):
    with pytest.raises(MethodError) as err:
        method_class(spec)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_parameters_have_defaults_and_unknown_ones_are_refused():
    assert make_method("bp").values == {"band_m": 0.05} and make_method("bp", {"band_m": 0.02}).values["band_m"] == 0.02
    allowed = ", ".join(sorted(method_class("mm2fsk").params)) or "none"
    with pytest.raises(MethodError) as err:
        make_method("mm2fsk", {"alpha": 1})
    assert str(err.value) == f"unknown parameter(s) alpha for mm2fsk; allowed: {allowed}"


def _bench(*overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *overrides], capture_output=True, text=True, timeout=300)


def test_a_method_of_ones_own_runs_from_the_command_line_and_gets_its_label(synth_root, tmp_path):
    out = tmp_path / "run"
    result = _bench("dataset=maroon", f"dataset.root={synth_root}", "method=custom",
                    "method._target_=examples.prior_only.PriorOnly", "prior=realsense", "freq=d10",
                    "store.dir=null", f"hydra.run.dir={out}")
    assert result.returncode == 0, result.stderr
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.method) == {"prior_only"} and set(rows.label) == {"Prior only"} and rows.valid_px.min() > 100
    from bench.report.tables import summarise
    assert list(summarise(rows).row) == ["Prior only (no radar)"]
    bad = _bench("dataset=maroon", f"dataset.root={synth_root}", "method=custom", "method._target_=nowhere.Mine",
                 "store.dir=null", f"hydra.run.dir={tmp_path / 'bad'}")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert "method 'nowhere.Mine' cannot be imported" in bad.stderr.strip().splitlines()[-1]


def test_user_mistakes_are_usage_errors_and_bugs_keep_their_traceback(tilted_plate):
    from bench.cli import error_line
    from methods.domain.errors import UsageError
    for mistake in ({"method": "2fsk", "freq": "d3"}, {"method": "2fsk", "freq": "d05", "prior": "lidar"},
                    {"method": "mm2fsk", "freq": "d05", "prior": "photogrammetry"},
                    {"method": "bp", "freq": "d05", "prior": 0.9}):
        with pytest.raises(UsageError) as err:
            reconstruct(tilted_plate, grid=GRID, **mistake)
        assert error_line(err.value) == str(err.value)          # one line on the command line
    assert error_line(ValueError("a bug")) is None               # re-raised with its traceback
