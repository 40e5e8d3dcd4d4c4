"""The success rule's coverage floor against what a radar can see at all (bench.report.scoring)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from bench.maroon.antennas import load_antenna_array
from bench.report.scoring import COVERAGE_FLOOR_PCT
from bench.synth.config import DISTANCE_RANGE_CM

BALL_RADIUS_M = 0.05      # the catalogue's ball (03_sphere): front at d - 2 cm, so its centre at d + 3 cm


def specular_cap_pct(centre_z_m: float) -> float:
    """Share (%) of a smooth ball's silhouette that reflects some transmitter into some receiver of the QAR50 array:
    the surface points whose normal bisects the directions to a transmitter and a receiver (specular reflection,
    geometric optics; the ball is small against its distance, so the directions are taken from its centre)."""
    array = load_antenna_array()
    centre = np.array([0.0, 0.0, centre_z_m])
    to_tx = array.tx_m - centre
    to_rx = array.rx_m - centre
    to_tx /= np.linalg.norm(to_tx, axis=1, keepdims=True)
    to_rx /= np.linalg.norm(to_rx, axis=1, keepdims=True)
    normals = (to_tx[:, None, :] + to_rx[None, :, :]).reshape(-1, 3)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    cap = ConvexHull(BALL_RADIUS_M * normals[:, :2])          # the pairs fill the cap: its projection's hull
    return 100.0 * cap.volume / (np.pi * BALL_RADIUS_M ** 2)


def test_the_specular_cap_of_a_ball_shrinks_with_distance_as_the_aperture_angle_squared():
    near, far = specular_cap_pct(0.33), specular_cap_pct(0.63)
    assert 5.0 < near < 6.0                                   # 30 cm: the 141 mm array subtends ~ +-13 deg
    half_angle_ratio = np.arctan(0.0705 / 0.63) / np.arctan(0.0705 / 0.33)
    assert abs(far / near - half_angle_ratio ** 2) < 0.05


def test_the_floor_passes_an_ideal_radar_on_a_ball_at_every_distance_and_fails_stray_pixels():
    """An ideal radar sees no more of a smooth ball than its specular cap; the floor must stay under it at the
    farthest distance the generator writes, or a perfect reconstruction would count as a failure. It must still
    fail the stray-pixel "successes" it exists for (26 of a 6,127-pixel silhouette)."""
    farthest_centre_m = DISTANCE_RANGE_CM[1] / 100 + 0.03
    assert COVERAGE_FLOOR_PCT < specular_cap_pct(farthest_centre_m)
    assert COVERAGE_FLOOR_PCT > 100 * 26 / 6127
