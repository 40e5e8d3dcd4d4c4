"""Conventions pinned by an asymmetric scene: a point target at +x, +y must appear right of centre in the upper
rows (row 0 = +y) with every method, and a frame with its rx/tx axes exchanged must not."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.synth.memory import TABLE1_FREQS_HZ, make_capture, simulate
from methods import reconstruct
from methods.domain.capture import Mesh, RadarGrid

TARGET_M = np.array([0.012, 0.020, 0.311])
GRID = RadarGrid((-0.03, -0.03, 0.26), (0.03, 0.03, 0.36), (31, 31, 51))     # 2 mm pixels
TARGET_PIXEL = (5, 21)                       # (row, col): y = 0.03 - 2 mm * 5, x = -0.03 + 2 mm * 21
CASES = [("bp", "d05", "none"), ("2fsk", "d05", "none"), ("3fsk", "d05_d10", "none"),
         ("mm2fsk", "d10", "photogrammetry")]


def capture_of(signal):
    # a flat photogrammetry 'mesh' through the target's depth: a perfect prior for MM-2FSK
    corners = np.array([[-0.04, -0.04, 0.0], [0.04, -0.04, 0.0], [0.04, 0.04, 0.0], [-0.04, 0.04, 0.0]])
    corners[:, 2] = TARGET_M[2]
    mesh = Mesh(vertices=corners, triangles=np.array([[0, 1, 2], [0, 2, 3]]), path=Path("memory"))
    return make_capture(signal, TABLE1_FREQS_HZ, GRID, mesh=mesh, transforms={"photogrammetry2radar": np.eye(4)})


@pytest.fixture(scope="module")
def signal():
    return simulate(TARGET_M[None], np.ones(1), TABLE1_FREQS_HZ)


def peak_pixel(rec):
    return tuple(int(i) for i in np.unravel_index(np.nanargmax(rec.magnitude), rec.magnitude.shape))


@pytest.mark.parametrize("method, config, prior", CASES)
def test_point_target_at_plus_x_plus_y_is_right_and_up(signal, method, config, prior):
    rec = reconstruct(capture_of(signal), method, config, prior=prior)
    row, col = peak_pixel(rec)
    assert abs(row - TARGET_PIXEL[0]) <= 1 and abs(col - TARGET_PIXEL[1]) <= 1     # measured: exact pixel
    assert row < 15 and col > 15                                                   # upper rows, right columns
    assert rec.depth_m[row, col] == pytest.approx(TARGET_M[2], abs=1e-3)


@pytest.mark.parametrize("method, config, prior", CASES[:2])
def test_exchanging_rx_and_tx_axes_moves_the_target(signal, method, config, prior):
    swapped = np.ascontiguousarray(signal.transpose(1, 0, 2))
    row, col = peak_pixel(reconstruct(capture_of(swapped), method, config, prior=prior))
    assert abs(row - TARGET_PIXEL[0]) + abs(col - TARGET_PIXEL[1]) > 10             # measured: (21, 5)
