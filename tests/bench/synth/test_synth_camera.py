"""The depth camera's errors as they arise (bench/synth/README.md, "Depth camera errors"): each switch does what it
claims on one rendered frame (no capture is written)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import ndimage

from bench.synth.config import SynthConfig
from bench.synth.materials import MATERIALS

pytest.importorskip("open3d")

from bench.synth.camera import depth as depth_camera  # noqa: E402  (needs Open3D)
from bench.synth.scenes import build_scene  # noqa: E402

QUIET = dict(disparity_sigma_px=0.0, dropout_fraction=0.0)


def _render(name: str, distance_m: float = 0.30, pose_seed: int = 3, **overrides):
    config = dataclasses.replace(SynthConfig(), **{**QUIET, **overrides})
    pose = depth_camera.perturbed_pose(depth_camera.nominal_pose(config), config, np.random.default_rng(pose_seed))
    return depth_camera.render(build_scene(name, distance_m), pose, config, np.random.default_rng(4)), pose


def test_segmentation_mask_is_shifted_spread_and_eroded_as_set():
    exact, _ = _render("01_plate")
    drawn, pose = _render("01_plate", mask_errors=True, mask_shift_px=2.0, mask_bleed_px=0)
    rows, cols = pose.mask_offset_px
    assert np.hypot(rows, cols) == pytest.approx(2.0, abs=0.75) and (rows, cols) != (0, 0)
    shifted = ndimage.shift(exact.mask == 255, (rows, cols), order=0)
    eroded = ndimage.binary_erosion(shifted, iterations=MATERIALS["metal"].mask_erosion_px)
    assert np.array_equal(drawn.mask == 255, eroded)                     # metal: pulled in along the outline
    bled, _ = _render("03_sphere", mask_errors=True, mask_shift_px=0.0, mask_bleed_px=2)
    plain, _ = _render("03_sphere")
    assert np.array_equal(bled.mask == 255, ndimage.binary_dilation(plain.mask == 255, iterations=2))   # wood


def _two_plates():
    """A wooden plate at 30 cm half covering another at 32.5 cm: a 2.5 cm depth edge with no wall between."""
    from bench.synth.scenes import Part, Scene
    from bench.synth.scenes.shapes import slab

    parts = (Part(slab(0.06, 0.08, 0.004, 0.30, -0.03), 0.35, (190, 140, 80), "wood"),
             Part(slab(0.09, 0.08, 0.004, 0.325, 0.015), 0.35, (190, 140, 80), "wood"))
    return Scene("two_plates", "two plates", parts)


def test_mixed_pixels_ramp_across_a_small_depth_edge_and_survive_a_10_mm_jump_rule():
    """The window's ramp crosses a 2.5 cm edge in 5 pixels of ~5 mm (kept by MAROON's 10 mm rule); the per-pixel
    random depths of the older model jump by more than 10 mm at most such pixels."""
    def frame(**overrides):
        config = dataclasses.replace(SynthConfig(), **{**QUIET, **overrides})
        return depth_camera.render(_two_plates(), depth_camera.nominal_pose(config), config, np.random.default_rng(4))

    clean = frame(edge_hole_px=0)                    # the true depth on both sides of the edge

    def mixed_and_kept(rendered):
        """Pixels between the two plates (the true depth 3 columns to each side on a plate) that the edge model
        moved by > 3 mm, and those of them within 10 mm of each row neighbour that has a depth (kept by the jump
        rule; 30 % of the band is lost to the left-right check)."""
        z, ref = rendered.depth_mm.astype(float), clean.depth_mm.astype(float)
        on_plates = (ref > 290) & (ref < 340)
        inner = np.zeros_like(on_plates)
        inner[:, 3:-3] = on_plates[:, :-6] & on_plates[:, 6:]
        mixed = inner & (z > 0) & (np.abs(z - ref) > 3)
        left, right = np.roll(z, 1, axis=1), np.roll(z, -1, axis=1)
        smooth = ((left == 0) | (np.abs(z - left) <= 10)) & ((right == 0) | (np.abs(z - right) <= 10))
        return mixed.sum(), (mixed & smooth).sum()

    mixed, kept = mixed_and_kept(frame(edge_fattening_px=2, edge_ramp=True))
    assert mixed > 50 and kept >= 0.9 * mixed
    mixed, kept = mixed_and_kept(frame(edge_fattening_px=2, flying_pixel_fraction=1.0))
    assert mixed > 50 and kept < 0.5 * mixed


def test_highlight_and_dark_holes_are_contiguous():
    """The metal pan loses the part of its dish that faces the camera within the highlight angle, in a few large
    blobs (a vertical can does not: the camera looks down on it at >= 15 deg); the black bottle loses much of its
    surface, the white one almost nothing."""
    plain, _ = _render("12_pan")
    holes, _ = _render("12_pan", camera_holes=True)
    lost = (plain.depth_mm > 0) & (holes.depth_mm == 0) & (plain.mask == 255)
    _, count = ndimage.label(lost)
    assert lost.sum() > 2000 and lost.sum() / count > 100                # blobs, not single pixels
    config = SynthConfig()
    _, cos_inc, geometry, _ = depth_camera._cast(build_scene("12_pan", 0.3), depth_camera.nominal_pose(config),
                                                 config)
    dish = lost & (geometry == 0)                                        # the handle is black plastic: dark holes
    incidence_deg = np.degrees(np.arccos(np.clip(cos_inc[dish], 0, 1)))
    assert np.mean(incidence_deg < 1.3 * MATERIALS["metal"].highlight_deg) > 0.8     # the rest: grazing, dark

    def lost_share(name):
        before, _ = _render(name)
        after, _ = _render(name, camera_holes=True)
        on = (before.mask == 255) & (before.depth_mm > 0)
        return float(np.mean(after.depth_mm[on] == 0))

    assert lost_share("16_black_bottle") > 0.3 > 0.05 > lost_share("04_bottle")


def test_ir_multipath_puts_a_mirroring_dihedral_behind_its_surface_and_leaves_a_plate():
    """Steel angle (a 90 deg dihedral, metal): each leg mirrors the other, so its pixels read the virtual image,
    centimetres behind; a flat plate mirrors nothing of the scene and is unchanged."""
    plain, _ = _render("22_steel_angle")
    mirrored, _ = _render("22_steel_angle", ir_multipath=True)
    on = (plain.mask == 255) & (plain.depth_mm > 0) & (mirrored.depth_mm > 0)
    shift_mm = mirrored.depth_mm[on].astype(float) - plain.depth_mm[on]
    assert np.median(shift_mm) > 10 and shift_mm.min() >= 0
    flat, _ = _render("01_plate")
    flat_mirrored, _ = _render("01_plate", ir_multipath=True)
    assert np.array_equal(flat.depth_mm, flat_mirrored.depth_mm)


def test_calibration_offsets_follow_the_stated_heavy_tailed_distribution():
    """Student-t (nu = 3) per axis, scaled to an RMS of the set size: RMS within 15 % over 4000 captures, and more
    captures beyond 2.5x the RMS than a Gaussian of the same RMS gives (its chi(3) tail: 0.05 %)."""
    config = SynthConfig(extrinsic_error_mm=3.0, extrinsic_error_deg=0.5, extrinsic_tail_dof=3.0)
    nominal = depth_camera.nominal_pose(config)
    rng = np.random.default_rng(0)
    offsets_mm = np.array([np.linalg.norm(depth_camera.perturbed_pose(nominal, config, rng).position_m
                                          - nominal.position_m) * 1e3 for _ in range(4000)])
    assert np.sqrt(np.mean(offsets_mm ** 2)) == pytest.approx(3.0, rel=0.15)
    assert np.mean(offsets_mm > 7.5) > 0.005


def test_depth_is_lost_below_the_minimum_range():
    near, _ = _render("08_two_objects", distance_m=0.22, min_depth_m=0.186)
    plain, _ = _render("08_two_objects", distance_m=0.22)
    on = (plain.mask == 255) & (plain.depth_mm > 0)
    assert np.all(near.depth_mm[on & (plain.depth_mm < 186)] == 0)       # the near plate (from 18.2 cm)
    assert np.array_equal(near.depth_mm[on & (plain.depth_mm >= 187)], plain.depth_mm[on & (plain.depth_mm >= 187)])


def test_depth_noise_grows_with_distance_squared_and_with_incidence():
    """sigma_z = Z^2 sigma_d / (f b) / cos(inc)^q: on the tilted plate (28 deg) q = 1 raises the measured spread by
    the mean 1 / cos(inc) of its pixels (within 10 %)."""
    def spread_mm(**overrides):
        noisy, _ = _render("02_tilted_plate", disparity_sigma_px=0.5, depth_focal_px=447.0, **overrides)
        clean, _ = _render("02_tilted_plate")
        on = (clean.mask == 255) & (clean.depth_mm > 0) & (noisy.depth_mm > 0)
        return float(np.std(noisy.depth_mm[on].astype(float) - clean.depth_mm[on]))

    config = SynthConfig()
    z_m, cos_inc, geometry, _ = depth_camera._cast(build_scene("02_tilted_plate", 0.3),
                                                   depth_camera.nominal_pose(config), config)
    on = (geometry == 0) & (cos_inc >= np.cos(np.radians(config.max_incidence_deg)))   # steeper: no depth
    expected = np.sqrt(np.mean((z_m[on] ** 2 * 0.5 / (447.0 * 0.05) * 1e3) ** 2 / cos_inc[on] ** 2) + 1 / 12)
    assert spread_mm(noise_angle_exponent=1.0) == pytest.approx(expected, rel=0.1)
    assert spread_mm() < spread_mm(noise_angle_exponent=1.0)
