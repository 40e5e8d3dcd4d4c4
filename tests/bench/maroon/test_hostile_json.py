"""Hostile JSON and the sizes it declares: nesting, number literals, encodings, string-typed numbers, grids of
1.6e9 pixels, erosion kernels of thousands of pixels, transforms that scale by 1e300. Each ends in one DatasetError
naming the JSON file, within bounded memory and time; properties (hypothesis) for the depth scan, the JSON reader
and the grid parser; the separable erosion equals the square one it replaced."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import ndimage

from bench.maroon import reader as maroon
from bench.maroon.jsonio import nesting_depth, read_json
from bench.maroon.limits import Limits, parse_limits, use_limits
from bench.stress import hostile_inputs as hi
from methods.domain.capture import RadarGrid
from methods.domain.errors import DatasetError
from metrics.masks import close_mask, erode_mask

from hostile_tools import RADAR, bounded, copy_capture, tree_digest

PROPERTY = settings(max_examples=80, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
CALIBRATION = f"{RADAR}/calibration.json"


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


@pytest.fixture
def capture(source_capture, tmp_path) -> Path:
    return copy_capture(source_capture, tmp_path / "root")


def _edit(capture: Path, relative: str, change) -> None:
    path = capture / relative
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def _volume(**changes):
    def change(data):
        data["000000"]["volume"].update(changes)
    return change


def _read_fails(capture: Path, relative: str, message: str) -> DatasetError:
    before = tree_digest(capture.parent.parent)
    with pytest.raises(DatasetError) as info, bounded():
        maroon.read_capture(capture)
    assert info.value.path == capture / relative, str(info.value)
    assert message in info.value.problem and "\n" not in str(info.value), str(info.value)
    assert tree_digest(capture.parent.parent) == before
    return info.value


JSON_TEXTS = {name: data for name, data in hi.json_cases().items()}
MESSAGES = {"json_deep_100k": "json_depth", "json_deep_objects": "json_depth", "json_int_400_digits":
            "json_number_chars", "json_int_5000_digits": "json_number_chars", "json_float_400_digits":
            "json_number_chars", "json_not_utf8": "not UTF-8"}


@pytest.mark.parametrize("relative", ["metadata.json", "alignment.json", CALIBRATION, "realsense/calibration.json"])
@pytest.mark.parametrize("case", sorted(JSON_TEXTS))
def test_hostile_json_ends_in_one_error_naming_the_file(capture, case, relative):
    (capture / relative).write_bytes(JSON_TEXTS[case])
    _read_fails(capture, relative, MESSAGES[case])


def test_a_400_digit_number_beyond_a_raised_limit_still_names_the_file(capture):
    """With json_number_chars raised, the 400-digit integer parses and then overflows a float: still one line."""
    (capture / "metadata.json").write_bytes(b'{"distance_meters": ' + b"9" * 400 + b"}")
    with use_limits(Limits(json_number_chars=10_000)):
        _read_fails(capture, "metadata.json", "too large for a float")


@pytest.mark.parametrize("change, message", [
    (_volume(bb_max=["0.15", 0.15, 0.4]), "must be a number"),                  # the string bb_max
    (_volume(bb_min=[-0.15, True, 0.2]), "must be a number"),
    (_volume(bb_max=[0.15, 0.15, None]), "must be a number"),
    (_volume(bb_min="-0.15"), "list of 3 numbers"),
    (_volume(grid_size=[40000, 40000, 1]), "grid_pixels"),                     # 1.6e9 pixels
    (_volume(grid_size=[1000, 1000, 1000]), "grid_voxels"),
    (_volume(grid_size=[301.0, 301, 201]), "positive integers"),
    (_volume(grid_size=[10 ** 60, 2, 2]), "grid_pixels"),
    (_volume(grid_size=[2, 2, 1], bb_min=[-1e-9, -1e-9, 0.3], bb_max=[1e-9, 1e-9, 0.3]), "below"),
    (_volume(bb_max=[0.15, 0.15, 1e308]), "in metres"),
])
def test_grid_values_are_checked_before_use(capture, change, message):
    _edit(capture, CALIBRATION, change)
    _read_fails(capture, CALIBRATION, message)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(mask_erosion=4000), "mask_erosion"),
    (lambda d: d.update(mask_erosion=10 ** 40), "mask_erosion"),
    (lambda d: d.update(distance_meters="0.3"), "must be a number"),
    (lambda d: d.update(mask_bb={"zmax": "0.7"}), "must be a number"),
    (lambda d: d.update(calibration="../../../etc"), "calibration must name a folder"),
])
def test_metadata_values_are_checked(capture, change, message):
    _edit(capture, "metadata.json", change)
    _read_fails(capture, "metadata.json", message)


@pytest.mark.parametrize("change, message", [
    (lambda d: d["rgb"].update(fx=1e-300), "focal lengths"),
    (lambda d: d["rgb"].update(cy=1e300), "focal lengths"),
    (lambda d: d["rgb"].update(width="640"), "must be a number"),
    (lambda d: d.update(capture={"scale": 10 ** 50}), "capture.scale"),
])
def test_camera_values_are_checked(capture, change, message):
    _edit(capture, "realsense/calibration.json", change)
    _read_fails(capture, "realsense/calibration.json", message)


def test_an_erosion_kernel_beyond_the_limit_on_a_fine_grid_names_metadata(capture):
    """mask_erosion 200 is 50 mm; on a grid of 0.1 mm pixels that is a 500-pixel kernel (limit 64)."""
    _edit(capture, "metadata.json", lambda d: d.update(mask_erosion=200))
    _edit(capture, CALIBRATION, _volume(bb_min=[-0.015, -0.015, 0.2], bb_max=[0.015, 0.015, 0.4]))
    _read_fails(capture, "metadata.json", "erosion_kernel_px")


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(photogrammetry2radar=(np.diag([1e300, 1e300, 1e300, 1.0])).tolist()), "scales lengths"),
    (lambda d: d.update(realsense2radar=[["1", 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "numbers"),
    (lambda d: d.update(realsense2radar=[[1, 0, 0, 1e9], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "translates"),
    (lambda d: d.update(realsense2radar=[[1, 0, 0], [0, 1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "4x4"),
])
def test_transforms_are_checked(capture, change, message):
    _edit(capture, "alignment.json", change)
    _read_fails(capture, "alignment.json", message)


def test_limits_parse_from_the_environment_syntax():
    limits = parse_limits("mesh_bytes=2GiB, image_pixels=50e6 signal_abs=1e20")
    assert limits.mesh_bytes == 2 << 30 and limits.image_pixels == 50_000_000 and limits.signal_abs == 1e20
    for bad in ("nope=1", "mesh_bytes=lots", "grid_pixels=0"):
        with pytest.raises(ValueError):
            parse_limits(bad)


# ---------------------------------------------------------------------------------------------- properties
def _reference_depth(text: str) -> int:
    """Nesting depth as a character-by-character scanner sees it, up to the first stray backslash (where JSON
    parsing would stop)."""
    depth = deepest = 0
    inside = escaped = False
    for char in text:
        if inside:
            escaped, inside = (False, inside) if escaped else (char == "\\", char != '"')
        elif char == "\\":
            break
        elif char == '"':
            inside = True
        elif char in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif char in "]}":
            depth -= 1
    return deepest


_JSON = st.recursive(st.none() | st.booleans() | st.floats(allow_nan=False) | st.integers() |
                     st.text(alphabet='ab"\\[]{}é\n', max_size=6),
                     lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(alphabet='k"\\[{', max_size=3),
                                                                                 inner, max_size=3), max_leaves=25)


@PROPERTY
@given(value=_JSON)
def test_nesting_depth_is_exact_on_json(value):
    text = json.dumps(value, ensure_ascii=False)
    assert nesting_depth(text.encode()) == _reference_depth(text)


@PROPERTY
@given(text=st.text(alphabet='[]{}"\\a1, ', max_size=60))
def test_nesting_depth_bounds_what_the_parser_can_reach(text):
    assert nesting_depth(text.encode()) >= _reference_depth(text)


@PROPERTY
@given(data=st.binary(max_size=300) | _JSON.map(lambda v: json.dumps(v).encode()),
       depth=st.integers(0, 200))
def test_read_json_returns_data_or_one_error(tmp_path, data, depth):
    path = tmp_path / "metadata.json"
    path.write_bytes(b"[" * depth + data + b"]" * depth)
    try:
        with bounded():
            read_json(path, kind=object)
    except DatasetError as err:
        assert err.path == path and "\n" not in err.problem
        return
    assert depth <= Limits().json_depth


_NUMBERISH = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10 ** 30, 10 ** 30),
                       st.text(max_size=4), st.booleans(), st.none(), st.lists(st.integers(0, 3), max_size=2))
_TRIPLE = st.one_of(st.lists(_NUMBERISH, min_size=3, max_size=3), _NUMBERISH, st.lists(_NUMBERISH, max_size=4))


@PROPERTY
@given(bb_min=_TRIPLE, bb_max=_TRIPLE,
       size=st.one_of(st.lists(st.integers(-2, 5000), min_size=3, max_size=3), _TRIPLE),
       drop=st.sampled_from([None, "bb_min", "bb_max", "grid_size"]))
def test_grid_parser_gives_a_bounded_grid_or_one_error(bb_min, bb_max, size, drop):
    entry = {"bb_min": bb_min, "bb_max": bb_max, "grid_size": size}
    if drop:
        entry.pop(drop)
    path = Path("calibration.json")
    try:
        grid = maroon._parse_grid(path, "000000", entry)
    except DatasetError as err:
        assert err.path == path and "\n" not in err.problem
        return
    limits = Limits()
    assert isinstance(grid, RadarGrid) and grid.size[0] >= 2 and grid.size[1] >= 2
    assert grid.size[0] * grid.size[1] <= limits.grid_pixels and math.prod(grid.size) <= limits.grid_voxels
    assert all(isinstance(v, float) and math.isfinite(v) and abs(v) <= 10 for v in grid.bb_min_m + grid.bb_max_m)
    assert grid.bb_min_m[2] > 0 and np.isfinite(grid.intrinsics()).all()


@PROPERTY
@given(seed=st.integers(0, 2 ** 32 - 1), shape=st.tuples(st.integers(1, 40), st.integers(1, 40)),
       fill=st.floats(0.0, 1.0), kernel=st.integers(1, 14))
def test_separable_erosion_and_closing_equal_the_square_ones(seed, shape, fill, kernel):
    """metrics.masks erodes and closes with a k x 1 then a 1 x k pass (O(k) per pixel, bounded time for any
    kernel the limits admit); the result is the k x k square's, retry loop included."""
    mask = np.random.default_rng(seed).random(shape) < fill
    square = np.ones((kernel, kernel), dtype=bool)
    expected = mask.copy()
    for k in range(kernel, 1, -1):
        eroded = ndimage.binary_erosion(mask, structure=np.ones((k, k), dtype=bool), border_value=1)
        if eroded.sum() > 10:
            expected = eroded
            break
    assert np.array_equal(erode_mask(mask, kernel), expected)
    if kernel > 1:
        padded = np.pad(mask, kernel)
        closed = ndimage.binary_closing(padded, structure=square)[kernel:-kernel, kernel:-kernel] | mask
        assert np.array_equal(close_mask(mask, kernel), closed)
