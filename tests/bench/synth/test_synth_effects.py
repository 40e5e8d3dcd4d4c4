"""Each effect of the realistic synthetic preset does what it claims (bench.synth.config.EFFECTS), on small inputs:
no capture is generated here (scenes are rendered or simulated directly; a few seconds in all)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.synth.config import C_M_PER_S, EFFECTS, PRESETS, SynthConfig, preset
from bench.synth.materials import MATERIALS
from bench.synth.meshes import rotation_matrix
from bench.synth.radar.model import (
    channel_gains,
    leg_gains,
    point_amplitude,
    simulate_frame,
    thermal_noise_sigma,
    wall_frame,
)

NO_NOISE = dict(disparity_sigma_px=0.0, dropout_fraction=0.0)   # holes at edges and steep slopes stay


def test_presets_ideal_is_the_default_and_every_effect_switch_changes_the_realistic_preset():
    assert PRESETS["ideal"] == SynthConfig()
    realistic = preset("realistic")
    realistic.validate()
    for name, off in EFFECTS.items():
        assert dataclasses.replace(realistic, **off) != realistic, f"{name}: switching it off changes nothing"
        assert all(getattr(SynthConfig(), k) == v for k, v in off.items()), f"{name}: 'off' is not the ideal value"
    with pytest.raises(ValueError, match="unknown synthetic preset"):
        preset("nope")


def test_fresnel_reflection_and_transmission_of_the_materials():
    assert MATERIALS["metal"].reflection == 1.0 and MATERIALS["metal"].transmission == 0.0
    n = np.sqrt(2.35)
    assert MATERIALS["plastic"].reflection == pytest.approx((n - 1) / (n + 1))          # 0.21
    assert 0.9 < MATERIALS["plastic"].transmission < 1.0
    assert MATERIALS["foam"].reflection < 0.01                                             # nearly transparent
    assert MATERIALS["wood"].transmission == 0.0                                           # solid wood: no wall


def _render(object_name: str, **overrides):
    pytest.importorskip("open3d")
    from bench.synth.camera import depth as depth_camera
    from bench.synth.scenes import build_scene

    config = dataclasses.replace(SynthConfig(), **{**NO_NOISE, **overrides})
    scene = build_scene(object_name, 0.30)
    pose = depth_camera.perturbed_pose(depth_camera.nominal_pose(config), config, np.random.default_rng(3))
    return depth_camera.render(scene, pose, config, np.random.default_rng(4)), config


def test_translucent_plastic_is_seen_behind_its_surface():
    plain, _ = _render("04_bottle")
    translucent, _ = _render("04_bottle", camera_materials=True)
    on_object = (plain.mask == 255) & (plain.depth_mm > 0) & (translucent.depth_mm > 0)
    shift_mm = translucent.depth_mm[on_object].astype(float) - plain.depth_mm[on_object]
    assert np.median(shift_mm) == pytest.approx(MATERIALS["plastic"].subsurface_bias_m * 1e3, abs=1.0)


def test_specular_metal_loses_camera_pixels():
    plain, _ = _render("01_plate")
    metal, _ = _render("01_plate", camera_materials=True)
    on_object = plain.mask == 255
    lost = np.mean(metal.depth_mm[on_object] == 0) - np.mean(plain.depth_mm[on_object] == 0)
    assert lost == pytest.approx(MATERIALS["metal"].dropout_fraction, abs=0.02)


def test_calibration_residual_shifts_the_prior_by_the_set_amount():
    """A pure translation of the camera by 3 mm moves the plate's back-projected points (with the nominal pose, as
    the reader does) by 3 mm; only the component along the plate's normal (z) changes its depth."""
    pytest.importorskip("open3d")
    from bench.synth.camera import depth as depth_camera
    from bench.synth.scenes import build_scene

    config = dataclasses.replace(SynthConfig(), extrinsic_error_mm=3.0, extrinsic_error_deg=0.0)
    nominal = depth_camera.nominal_pose(config)
    pose = depth_camera.perturbed_pose(nominal, config, np.random.default_rng(3))
    offset_m = pose.position_m - nominal.position_m
    assert np.linalg.norm(offset_m) == pytest.approx(3e-3, rel=1e-9)
    rotated = depth_camera.perturbed_pose(nominal, dataclasses.replace(config, extrinsic_error_deg=0.5),
                                          np.random.default_rng(3))
    angle = np.degrees(np.arccos((np.trace(rotated.rotation.T @ nominal.rotation) - 1) / 2))
    assert angle == pytest.approx(0.5, rel=1e-6)

    def plate_z_m(camera_pose):
        frame = depth_camera.render(build_scene("01_plate", 0.30), camera_pose,
                                    dataclasses.replace(config, **NO_NOISE), np.random.default_rng(0))
        v, u = np.nonzero((frame.mask == 255) & (frame.depth_mm > 0))
        z_mm = frame.depth_mm[v, u].astype(float)
        cam = np.stack([(u - config.principal_point_px[0]) * z_mm / config.focal_px,
                        (v - config.principal_point_px[1]) * z_mm / config.focal_px, z_mm], 1)
        return np.median((cam * 1e-3) @ nominal.rotation.T + nominal.position_m, axis=0)[2]

    # depths are stored in whole mm: compare medians over the plate (sub-mm through the plane's tilt)
    assert plate_z_m(pose) - plate_z_m(nominal) == pytest.approx(-offset_m[2], abs=0.3e-3)


def test_edge_pixels_fatten_the_foreground_and_fly_between_the_surfaces():
    holes, _ = _render("01_plate")
    edges, config = _render("01_plate", edge_fattening_px=3, flying_pixel_fraction=0.5)
    valid_ideal, valid_edges = holes.depth_mm > 0, edges.depth_mm > 0
    assert valid_edges.sum() > valid_ideal.sum()                              # fewer holes at the plate's rim
    between = valid_edges & (edges.depth_mm > 340) & (edges.depth_mm < 950)   # neither the plate nor the wall
    assert between.sum() > 100
    assert between[holes.mask == 255].sum() < between.sum()                   # mostly off the object: flying


def test_slant_bias_grows_with_incidence():
    facing, _ = _render("01_plate")
    facing_b, config = _render("01_plate", slant_bias_px=0.5)
    tilted, _ = _render("02_tilted_plate")
    tilted_b, _ = _render("02_tilted_plate", slant_bias_px=0.5)

    def bias_mm(a, b):
        both = (a.mask == 255) & (a.depth_mm > 0) & (b.depth_mm > 0)
        return np.mean(b.depth_mm[both].astype(float) - a.depth_mm[both])

    assert bias_mm(tilted, tilted_b) > bias_mm(facing, facing_b) + 0.1
    assert bias_mm(tilted, tilted_b) > 0


def _small_plate(normal_tilt_deg: float, centre_m=(0.0, 0.0, 0.30), half_m=0.02, spacing_m=0.8e-3):
    """Samples of a square plate facing -z, then tilted about y: points, normals, areas."""
    g = np.arange(-half_m, half_m + 1e-12, spacing_m)
    x, y = np.meshgrid(g, g)
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    rotation = rotation_matrix([0, 1, 0], normal_tilt_deg)
    normals = np.tile([0.0, 0.0, -1.0], (len(points), 1)) @ rotation.T
    return points @ rotation.T + centre_m, normals, np.full(len(points), spacing_m ** 2)


def test_specular_plate_tilted_away_returns_less_than_one_facing_the_array():
    from bench.maroon.antennas import load_antenna_array

    antennas = load_antenna_array()
    tx, rx = antennas.tx_m[::6], antennas.rx_m[::6]
    freqs = np.linspace(76e9, 78e9, 3)
    lobe = np.full(1, np.deg2rad(MATERIALS["metal"].lobe_deg))

    def energy(tilt_deg, specular):
        points, normals, areas = _small_plate(tilt_deg)
        frame = simulate_frame(points, areas, tx, rx, freqs, normals if specular else None,
                               np.repeat(lobe, len(points)) if specular else None)
        return float(np.sum(np.abs(frame) ** 2))

    specular_ratio = energy(35.0, True) / energy(0.0, True)
    cosine_ratio = energy(35.0, False) / energy(0.0, False)
    assert specular_ratio < 0.5 * cosine_ratio
    assert specular_ratio < 0.1


def test_leg_gains_element_pattern_and_lobe_values():
    point = np.array([[0.0, 0.0, 0.30]])
    antennas = np.array([[0.0, 0.0, 0.0], [0.30, 0.0, 0.0]])
    gain = leg_gains(point, antennas, element_exponent=1.0)
    assert gain[0] == pytest.approx([1.0, np.cos(np.pi / 4)])
    lobe = leg_gains(point, antennas, normals=np.array([[0.0, 0.0, -1.0]]), lobe_rad=np.array([np.pi / 8]))
    assert lobe[0] == pytest.approx([1.0, np.exp(-0.5 * 2.0 ** 2)])           # 45 deg off the normal = 2 lobes


def test_back_walls_of_transmissive_parts_are_sampled_behind_the_front():
    pytest.importorskip("open3d")
    from bench.synth.sampling import back_wall_samples, visible_samples
    from bench.synth.scenes import build_scene

    parts = build_scene("04_bottle", 0.30).parts
    tris = [p.tris_m for p in parts]
    front = visible_samples(tris, 2e-3)
    back = back_wall_samples(tris, [True], 2e-3)
    assert len(back.areas_m2) > 0.5 * len(front.areas_m2)
    assert np.median(back.points_m[:, 2]) > np.median(front.points_m[:, 2]) + 0.03      # the far half of the body
    assert np.all(back.normals[:, 2] < 0.2)                                              # reversed: towards the array
    assert len(back_wall_samples(tris, [False], 2e-3).areas_m2) == 0                     # opaque: nothing


def test_channel_residual_has_the_set_spread():
    config = dataclasses.replace(SynthConfig(), channel_amplitude_db=0.5, channel_phase_deg=5.0)
    gains = channel_gains(4000, 1, config, np.random.default_rng(0))[:, 0, 0]
    # g_rx * g_tx: the transmitter's factor is one common draw; remove it with the median
    gains = gains / np.exp(1j * np.median(np.angle(gains))) / np.median(np.abs(gains))
    assert np.std(20 * np.log10(np.abs(gains))) == pytest.approx(0.5, rel=0.1)
    assert np.degrees(np.std(np.angle(gains))) == pytest.approx(5.0, rel=0.1)


def test_wall_image_source_matches_the_sampled_plane_and_its_range():
    """The wall as an image source equals the model's sum over a large sampled plane (stationary phase) within the
    edge-diffraction ripple, and |s| = Gamma lambda / (2 R) for a monostatic pair."""
    config = dataclasses.replace(SynthConfig(), wall_reflection=1.0, wall_distance_m=1.0)
    freq = np.array([77e9])
    origin = np.zeros((1, 3))
    s = wall_frame(origin, origin, freq, config)[0, 0, 0]
    wavelength = C_M_PER_S / freq[0]
    assert abs(s) == pytest.approx(wavelength / 2.0, rel=1e-5)
    distance_m, half_m, step_m = 0.5, 0.25, 0.5e-3
    g = np.arange(-half_m, half_m, step_m) + step_m / 2
    x, y = np.meshgrid(g, g)
    r = np.sqrt(x ** 2 + y ** 2 + distance_m ** 2)
    sampled = np.sum(step_m ** 2 * np.exp(-2j * np.pi * freq[0] * 2 * r / C_M_PER_S) / r ** 2)
    near = wall_frame(origin, origin, freq, dataclasses.replace(config, wall_distance_m=distance_m))[0, 0, 0]
    assert abs(sampled) == pytest.approx(abs(near), rel=0.25)
    assert abs(np.angle(sampled / near)) < 0.3


def test_point_amplitude_units_and_datasheet_noise_level():
    area_m2, wavelength = 1e-4, C_M_PER_S / 77e9
    assert point_amplitude(4 * np.pi * area_m2 ** 2 / wavelength ** 2, 77e9) == pytest.approx(area_m2)
    # k T F B (4 pi)^2 / (P_t G_t G_r), per real part: 0 dBm, 6 dBi elements, NF 12 dB, 1 MHz
    expected = np.sqrt(1.380649e-23 * 290 * 10 ** 1.2 * 1e6 * (4 * np.pi) ** 2 / (1e-3 * 10 ** 1.2) / 2)
    assert thermal_noise_sigma(preset("realistic")) == pytest.approx(expected)


def test_mount_is_seen_but_is_not_ground_truth():
    pytest.importorskip("open3d")
    from bench.synth.camera import depth as depth_camera
    from bench.synth.scenes import build_scene

    scene = build_scene("03_sphere", 0.30)
    mounted = scene.with_mount()
    assert len(mounted.parts) == len(scene.parts) + 1 and not mounted.parts[-1].ground_truth
    assert np.array_equal(mounted.tris_m, scene.tris_m)
    config = dataclasses.replace(SynthConfig(), **NO_NOISE)
    pose = depth_camera.nominal_pose(config)
    plain = depth_camera.render(scene, pose, config, np.random.default_rng(0))
    with_post = depth_camera.render(mounted, pose, config, np.random.default_rng(0))
    assert np.array_equal(plain.mask, with_post.mask)                        # the post is not in the object mask
    assert np.sum((with_post.depth_mm > 0) & (with_post.depth_mm < 400)) > np.sum(
        (plain.depth_mm > 0) & (plain.depth_mm < 400))                       # but the camera sees it


def test_ground_truth_registration_residual_has_the_set_size():
    from bench.synth.parts import _registration_residual

    config = dataclasses.replace(SynthConfig(), gt_registration_mm=1.0, gt_registration_deg=0.2)
    residual = _registration_residual(config, np.random.default_rng(0))
    assert np.linalg.norm(residual[:3, 3]) == pytest.approx(1e-3)
    assert np.degrees(np.arccos((np.trace(residual[:3, :3]) - 1) / 2)) == pytest.approx(0.2, rel=1e-6)
    assert np.array_equal(_registration_residual(SynthConfig(), np.random.default_rng(0)), np.eye(4))


def test_depth_scale_error_scales_the_camera_depth():
    plain, _ = _render("01_plate")
    scaled, _ = _render("01_plate", depth_scale_error=0.02)
    both = (plain.mask == 255) & (plain.depth_mm > 0) & (scaled.depth_mm > 0)
    ratio = np.median(scaled.depth_mm[both].astype(float) / plain.depth_mm[both])
    assert ratio == pytest.approx(1.02, abs=0.004)


def test_app_names_a_bad_preset_or_setting_in_one_line(tmp_path):
    from omegaconf import OmegaConf

    from bench import cli
    from bench.harness.app import ensure_synthetic

    dataset = OmegaConf.create({"generate": {"distances": [30], "objects": ["01_plate"]}})
    for synth, problem in (({"preset": "nope", "overrides": {}}, "unknown synthetic preset 'nope'"),
                           ({"preset": "realistic", "overrides": {"bogus": 1}}, "bogus"),
                           ({"preset": "ideal", "overrides": {"scattering": "mirror"}}, "scattering must be")):
        with pytest.raises(cli.UserError, match=problem) as err:
            ensure_synthetic(dataset, tmp_path / "root", OmegaConf.create(synth))
        assert err.value.what == "synth"
    assert not (tmp_path / "root").exists()                     # nothing generated, nothing claimed


def test_skipped_sideways_samples_change_the_frame_by_less_than_1e4():
    """radar_scene skips samples whose lobe gain towards every antenna is < 1e-2: the frame of a cylinder's flank
    with and without them agrees to 1e-4 of its peak."""
    from bench.maroon.antennas import load_antenna_array
    from bench.synth.radar import scene as radar_scene
    from bench.synth.sampling import SurfaceSamples

    antennas = load_antenna_array()
    angles = np.linspace(-np.pi / 2, np.pi / 2, 400)                 # a half cylinder r = 4 cm facing the array
    points = np.column_stack([0.04 * np.sin(angles), np.zeros_like(angles), 0.30 - 0.04 * np.cos(angles)])
    normals = np.column_stack([np.sin(angles), np.zeros_like(angles), -np.cos(angles)])
    samples = SurfaceSamples(points, normals, np.full(len(points), 1e-6), np.zeros(len(points), dtype=np.int64))
    lobe = np.deg2rad([MATERIALS["plastic"].lobe_deg])
    gains = leg_gains(points, np.concatenate([antennas.rx_m, antennas.tx_m]), normals, np.repeat(lobe, len(points)))
    keep = gains.max(axis=1) >= radar_scene.LOBE_CUTOFF
    assert 0 < (~keep).sum() < len(keep)                             # some samples are skipped
    freqs = np.array([77e9])
    full = simulate_frame(points, samples.areas_m2, antennas.tx_m, antennas.rx_m, freqs, normals,
                          np.repeat(lobe, len(points)))
    config = dataclasses.replace(SynthConfig(), scattering="specular")
    skipped = radar_scene._simulate(samples, samples.areas_m2, points, lobe, config, antennas, freqs, "cpu")
    assert np.abs(skipped - full).max() < 1e-4 * np.abs(full).max()


def test_ground_truth_smoothing_rounds_edges_flattens_ripples_and_keeps_flat_faces():
    """MAROON's smoothed photogrammetry mesh (30 Laplacian steps): flat faces stay put, edges round off inward,
    ripples lose amplitude with every step, the mesh stays closed with its winding; 0 steps = the exact mesh."""
    from bench.synth.camera.photogrammetry import smoothed_mesh
    from bench.synth.meshes import extrude_strip, indexed, triangle_normals

    plate = extrude_strip(np.array([-0.06, 0.06]), [0.3, 0.3], [0.304, 0.304], 0.12)
    assert smoothed_mesh(plate, 0, 0) is plate
    smooth = smoothed_mesh(plate, 30, 1)
    vertices = smooth.reshape(-1, 3)
    centre = np.linalg.norm(vertices[:, :2], axis=1) < 0.02                 # the face's middle: no neighbour off it
    assert np.abs(vertices[centre & (vertices[:, 2] < 0.302), 2] - 0.3).max() < 1e-9
    assert 0.05 < np.abs(vertices[:, 0]).max() < 0.06 - 5e-4                # edges pulled in by more than 0.5 mm

    def faces_per_edge(tris):
        _, triangles = indexed(tris)
        edges = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        return np.bincount(np.unique(edges, axis=0, return_counts=True)[1])

    # connectivity kept: the subdivided mesh's edges (each of the extrusion's few seam edges split in two)
    assert list(faces_per_edge(smooth)) == list(faces_per_edge(smoothed_mesh(plate, 0, 1)))
    assert faces_per_edge(smooth)[1] == 2 * faces_per_edge(plate)[1]
    volume = np.einsum("ij,ij->i", smooth[:, 0], np.cross(smooth[:, 1], smooth[:, 2])).sum() / 6
    assert 0.8 * 0.12 * 0.12 * 0.004 < volume < 0.12 * 0.12 * 0.004        # outward winding kept; it shrinks
    x = np.linspace(-0.07, 0.07, 57)
    front = 0.3 + 0.005 * np.sin(2 * np.pi * x / 0.03)
    sheet = extrude_strip(x, front, front + 0.003, 0.12)
    amplitudes = []
    for steps in (0, 10, 30):
        tris = smoothed_mesh(sheet, steps, 1)
        normals, _ = triangle_normals(tris)
        inner = (np.abs(tris[..., 0]).max(axis=1) < 0.05) & (np.abs(tris[..., 1]).max(axis=1) < 0.03)
        facing = tris[(normals[:, 2] < -0.5) & inner]                     # the front, away from its edges
        amplitudes.append(np.ptp(facing[..., 2]) / 2)
    assert amplitudes[0] == pytest.approx(0.005, abs=2e-4) and amplitudes[0] > amplitudes[1] > amplitudes[2] > 0.002


def test_indexed_merges_corners_exactly_as_numpy_unique():
    """meshes.indexed (pandas group numbers) against np.unique(axis=0) on a random soup with shared corners."""
    from bench.synth.meshes import indexed

    rng = np.random.default_rng(5)
    corners = rng.normal(size=(300, 3))
    corners[:, 0][::7] = corners[0, 0]                      # ties in the first coordinate: the order is by all three
    tris = corners[rng.integers(0, 300, size=(500, 3))]
    vertices, triangles = indexed(tris)
    expected, inverse = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
    assert np.array_equal(vertices, expected) and np.array_equal(triangles.ravel(), inverse.ravel())
    assert triangles.dtype == np.int64 and np.array_equal(vertices[triangles], tris)


def _dihedral(material_reflection: float):
    """A 90-degree metal corner (two 6 x 6 cm plates at +-45 deg about y) opening towards the array, edge at
    z = 0.3 m."""
    from bench.synth.meshes import extrude_strip, transform

    plate = extrude_strip(np.array([0.0, 0.06]), [0.0, 0.0], [0.002, 0.002], 0.06)   # x 0..6 cm from the edge
    left = transform(plate, rotation_matrix([0, 1, 0], 45.0), [0.0, 0.0, 0.3])
    right = transform(plate * [-1, 1, 1], rotation_matrix([0, 1, 0], -45.0), [0.0, 0.0, 0.3])
    right = right[:, [0, 2, 1]]                                  # mirrored in x: restore the outward winding
    return [left, right], np.full(2, material_reflection)


def test_dihedral_double_bounce_returns_from_the_corner_and_outshines_its_direct_echo():
    """Second-order multipath (opt-in `multipath`): every traced pair of a 90-degree corner has the unfolded path of
    the corner's edge (retro-reflection: 2 x 0.3 m), its amplitude scales with Gamma^2, and the metal corner returns
    more by the double bounce than by its direct (single, quasi-specular) echo."""
    pytest.importorskip("open3d")
    from bench.maroon.antennas import load_antenna_array
    from bench.synth.radar import multipath
    from bench.synth.sampling import visible_samples

    antennas = load_antenna_array(all_elements=True)
    parts, metal = _dihedral(1.0)
    samples = visible_samples(parts, 0.9e-3)
    lobe = np.deg2rad([15.0, 15.0])
    pairs = multipath.bounce_pairs(parts, samples, metal, lobe)
    assert len(pairs.hop_m) > 0.5 * len(samples.areas_m2)        # most rays into the corner come back out of it
    unfolded = np.linalg.norm(pairs.first_m, axis=1) + pairs.hop_m + np.linalg.norm(pairs.second_m, axis=1)
    # the corner retro-reflects: the shortest unfolded path is twice the edge's range; off-axis rays return offset
    # from the centre, which lengthens them by about offset^2 / range (< 1.5 cm here)
    assert abs(unfolded.min() - 0.6) < 5e-4 and np.median(unfolded) - 0.6 < 6e-3 and unfolded.max() < 0.615
    plastic = multipath.bounce_pairs(parts, samples, np.full(2, 0.21), lobe)
    assert np.allclose(plastic.amplitude, 0.21 ** 2 * pairs.amplitude)
    freqs = np.linspace(72e9, 82e9, 4)
    double = multipath.simulate_pairs(pairs, antennas.tx_m, antennas.rx_m, freqs)
    direct = simulate_frame(samples.points_m, metal[samples.part] * samples.areas_m2, antennas.tx_m, antennas.rx_m,
                            freqs, samples.normals, lobe[samples.part])
    assert np.mean(np.abs(double) ** 2) > 4 * np.mean(np.abs(direct) ** 2)
