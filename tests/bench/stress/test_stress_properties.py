"""Stress suite, property-based (hypothesis): the reader turns any frame-file content into a RadarFrame or a
DatasetError, never another exception; the metrics are finite or NaN only when nothing is comparable,
non-negative, and exact on shifted planes."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from bench.maroon import reader as maroon
from bench.synth.memory import make_capture, square_grid
from methods.domain.capture import Mesh, RadarGrid
from methods.domain.errors import DatasetError
from methods.domain.lattice import triangulated_vertices
from metrics.evaluate import METRIC_COLUMNS, TRIANGULATION_THRESHOLD_M, evaluate, ground_truth

FAST = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
GRID = RadarGrid((-0.15, -0.15, 0.25), (0.15, 0.15, 0.40), (301, 301, 151))
PLATE_Z_M = 0.40


def _read_frame(tmp_path: Path, write) -> None:
    radar_dir = tmp_path / "radar"
    (radar_dir / "calibrated_data").mkdir(parents=True, exist_ok=True)
    write(radar_dir / "calibrated_data" / "000000.npy")
    try:
        frame = maroon.read_radar_frame(radar_dir, 0, GRID)
    except DatasetError as err:
        assert "000000.npy" in str(err)
        return
    assert frame.signal.shape[:2] == (94, 94) and np.isfinite(frame.signal.view(np.float32)).all()
    assert frame.freqs_hz.min() >= 1e9 and np.all(np.diff(frame.freqs_hz) > 0)


@FAST
@given(data=st.binary(max_size=400))
def test_random_bytes_in_a_frame_file_give_a_dataset_error(tmp_path, data):
    _read_frame(tmp_path, lambda p: p.write_bytes(data))


@FAST
@given(data=st.binary(max_size=200))
def test_a_valid_npy_header_with_random_payload_gives_a_dataset_error(tmp_path, data):
    def write(path):
        holder = np.empty((), dtype=object)
        holder[()] = {"xr": 0}
        np.save(path, holder, allow_pickle=True)
        raw = path.read_bytes()
        path.write_bytes(raw[:128] + data)             # header kept, pickle replaced
    _read_frame(tmp_path, write)


_ARRAYS = hnp.arrays(st.sampled_from([np.complex64, np.complex128, np.float64, np.int64, np.bool_]),
                     hnp.array_shapes(min_dims=0, max_dims=3, max_side=4))     # NaN/Inf included
_VALUES = st.one_of(_ARRAYS, st.integers(), st.floats(), st.text(max_size=5), st.none(),
                    st.lists(st.integers(), max_size=3),
                    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
_FREQS = st.one_of(_VALUES, st.just(np.linspace(72e9, 82e9, 4)), st.just(np.linspace(72, 82, 4)))
_XR = st.one_of(_VALUES, st.just(np.ones((96, 96, 4), np.complex64)), st.just(np.ones((94, 94, 3), np.complex64)),
                st.just(np.full((94, 94, 4), np.nan, np.complex64)))


@FAST
@given(frame=st.fixed_dictionaries({}, optional={"xr": _XR, "fvec": _FREQS, "timestamp_us": _VALUES,
                                                 "number_of_measurements": _VALUES}),
       extra=st.dictionaries(st.text(max_size=4), _VALUES, max_size=2))
def test_random_frame_dicts_give_a_frame_or_a_dataset_error(tmp_path, frame, extra):
    def write(path):
        holder = np.empty((), dtype=object)
        holder[()] = {**extra, **frame}
        np.save(path, holder, allow_pickle=True)
    _read_frame(tmp_path, write)


@pytest.fixture(scope="module")
def plate_gt():
    """Ground truth of a flat plate at PLATE_Z_M covering an 11 x 11 pixel grid (mesh = radar space)."""
    grid = square_grid(0.01, 11, 0.3, 0.5, 11)
    vertices = np.array([[-0.05, -0.05, PLATE_Z_M], [0.05, -0.05, PLATE_Z_M], [0.05, 0.05, PLATE_Z_M],
                         [-0.05, 0.05, PLATE_Z_M]])
    mesh = Mesh(vertices, np.array([[0, 1, 2], [0, 2, 3]]), Path("memory"))
    capture = make_capture(np.zeros((94, 94, 1), np.complex64), [80e9], grid, mesh=mesh,
                           transforms={"photogrammetry2radar": np.eye(4)})
    return ground_truth(capture, grid)


_DEPTHS = hnp.arrays(np.float64, (11, 11), elements=st.one_of(st.floats(0.2, 0.6), st.just(np.nan)))


@FAST
@given(depth_m=_DEPTHS)
def test_metrics_are_finite_nonnegative_or_nan_only_when_nothing_is_comparable(plate_gt, depth_m):
    metrics = evaluate(depth_m, plate_gt)
    comparable = triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M).any()
    for name in METRIC_COLUMNS:
        value = metrics[name]
        assert np.isfinite(value) == comparable, (name, value)
        assert not comparable or value >= 0


@FAST
@given(shift_m=st.floats(-0.05, 0.05))
def test_metrics_of_a_shifted_plane_equal_the_shift(plate_gt, shift_m):
    metrics = evaluate(np.full((11, 11), PLATE_Z_M + shift_m), plate_gt)
    for name in METRIC_COLUMNS:
        assert metrics[name] == pytest.approx(abs(shift_m) * 100, abs=1e-6), name
