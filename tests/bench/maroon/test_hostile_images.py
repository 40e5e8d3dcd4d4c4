"""Hostile depth and mask PNGs: decompression bombs (declared 20000 x 20000 and 30000 x 30000, and a real one),
images beyond the configured pixel limit, wrong formats; each ends in one DatasetError naming the image, decided
from the header before any pixel is decoded. Property: any byte mutation of a real depth PNG gives a uint16 image
or one error, within bounded memory and time."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bench.maroon import reader
from bench.maroon.images import read_binary_mask, read_uint16_png
from bench.maroon.limits import Limits, use_limits
from bench.stress import hostile_inputs as hi
from methods.domain.errors import DatasetError

from hostile_tools import bounded, copy_capture, tree_digest

PROPERTY = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
DEPTH, MASK = "realsense/depth/000000.png", "realsense/mask/000000.png"


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


@pytest.fixture(scope="module")
def depth_png(source_capture) -> bytes:
    return (source_capture / DEPTH).read_bytes()


CASES = {
    "declared_20000x20000_depth": (DEPTH, lambda: hi.png_declaring(20000, 20000), "decompression bomb"),
    "declared_30000x30000_mask": (MASK, lambda: hi.png_declaring(30000, 30000, 8), "decompression bomb"),
    "declared_5000x5000_depth": (DEPTH, lambda: hi.png_declaring(5000, 5000), "image_pixels"),
    "real_bomb_6000x6000_mask": (MASK, lambda: hi.png_bomb(6000, 6000), "image_pixels"),
    "declared_1x2e9_mask": (MASK, lambda: hi.png_declaring(1, 2_000_000_000, 1), "decompression bomb"),
    "jpeg_named_png": (DEPTH, lambda: b"\xff\xd8\xff\xe0" + b"\0" * 64, "not a readable image"),
    "truncated_header": (MASK, lambda: hi.png_declaring(640, 480, 8)[:20], "not a readable image"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_hostile_image_ends_in_one_error_naming_it(source_capture, tmp_path, case):
    relative, build, message = CASES[case]
    capture = copy_capture(source_capture, tmp_path / "root")
    (capture / relative).write_bytes(build())
    before = tree_digest(tmp_path / "root")
    with pytest.raises(DatasetError) as info, bounded(extra_memory_bytes=512 << 20):
        reader.read_capture(capture)
    assert info.value.path == capture / relative and message in info.value.problem, str(info.value)
    assert "\n" not in str(info.value) and tree_digest(tmp_path / "root") == before


def test_the_pixel_limit_is_configurable(source_capture, tmp_path):
    path = tmp_path / "000000.png"
    path.write_bytes((source_capture / DEPTH).read_bytes())
    assert read_uint16_png(path).shape == (480, 640)
    with use_limits(Limits(image_pixels=640 * 480 - 1)), pytest.raises(DatasetError, match="image_pixels"):
        read_uint16_png(path)
    with use_limits(Limits(image_bytes=100)), pytest.raises(DatasetError, match="image_bytes"):
        read_uint16_png(path)


@PROPERTY
@given(edits=st.lists(st.tuples(st.integers(min_value=0), st.integers(0, 255)), min_size=1, max_size=6),
       cut=st.one_of(st.none(), st.integers(min_value=0)), mask=st.booleans())
def test_mutated_depth_png_gives_an_image_or_one_error(depth_png, tmp_path, edits, cut, mask):
    data = bytearray(depth_png)
    for position, value in edits:
        data[position % 64 if position % 3 else position % len(data)] = value    # header bytes twice as often
    if cut is not None:
        data = data[: cut % (len(data) + 1)]
    path = tmp_path / "000000.png"
    path.write_bytes(bytes(data))
    try:
        with bounded(extra_memory_bytes=512 << 20):
            image = read_binary_mask(path) if mask else read_uint16_png(path)
    except DatasetError as err:
        assert err.path == path and "\n" not in err.problem
        return
    assert image.ndim == 2 and image.size <= Limits().image_pixels
    assert image.dtype == (bool if mask else np.uint16)


@PROPERTY
@given(width=st.integers(1, 2 ** 31 - 1), height=st.integers(1, 2 ** 31 - 1),
       mode=st.sampled_from([(16, 0), (8, 0), (8, 2), (8, 6), (1, 0), (16, 6)]))
def test_any_declared_size_is_decided_from_the_header(tmp_path, width, height, mode):
    """The data is 1 kB of zeros: small images decode (short data is an error), large ones never reach decoding."""
    path = tmp_path / "000000.png"
    path.write_bytes(hi.png_declaring(width, height, *mode))
    try:
        with bounded(seconds=10, extra_memory_bytes=256 << 20):
            mask = read_binary_mask(path)
    except DatasetError as err:
        if width * height > Limits().image_pixels:
            assert "image_pixels" in err.problem or "decompression bomb" in err.problem, err.problem
        return
    assert mask.shape == (height, width) and width * height <= 8 * 1024
