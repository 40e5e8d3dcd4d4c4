"""The object catalogue: wide enough for statistics (the paper's categories) and well posed for scoring (every part
of every object inside its capture's radar volume and MAROON's default mask_bb at every distance the generator
accepts)."""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.config import DISTANCE_RANGE_CM
from bench.synth.materials import MATERIALS
from bench.synth.scenes import CATALOGUE, CATALOGUES, FULL_CATALOGUE, build_scene
from bench.synth.writer import RADAR_HALF_DEPTH_M, RADAR_HALF_WIDTH_M, maroon_default_mask_bb

# The ground-truth mesh is written with a registration residual (realistic preset: 1 mm and 0.2 deg about the radar
# origin, which moves a point at most ~1.3 mm within 0.15 m of the axis): parts keep this much clear of every bound.
MARGIN_M = 2e-3


@pytest.mark.parametrize("name", list(FULL_CATALOGUE))
def test_every_part_lies_inside_the_radar_volume_and_mask_bb_at_every_distance(name):
    for distance_cm in range(DISTANCE_RANGE_CM[0], DISTANCE_RANGE_CM[1] + 1):
        d_m = distance_cm / 100
        bounds = maroon_default_mask_bb(d_m)
        lo_z = max(bounds.get("zmin", -np.inf), d_m - RADAR_HALF_DEPTH_M) + MARGIN_M
        hi_z = min(bounds.get("zmax", np.inf), d_m + RADAR_HALF_DEPTH_M) - MARGIN_M
        for part in build_scene(name, d_m).parts:
            corners = part.tris_m.reshape(-1, 3)
            assert corners[:, 2].min() >= lo_z and corners[:, 2].max() <= hi_z, (name, distance_cm, part.material)
            assert np.abs(corners[:, :2]).max() <= RADAR_HALF_WIDTH_M - MARGIN_M, (name, distance_cm)


def test_a_part_in_front_of_mask_bb_zmin_is_caught():
    """The check above fails on the old design of 08_two_objects (its plate from 25.5 cm, zmin 0.26 m)."""
    from bench.synth.scenes.shapes import slab

    plate = slab(0.07, 0.09, 0.004, 0.30 - 0.045)
    assert plate[..., 2].min() < maroon_default_mask_bb(0.30)["zmin"]


def test_the_catalogue_spans_the_papers_categories():
    assert len(FULL_CATALOGUE) >= 24 and set(CATALOGUE) < set(FULL_CATALOGUE)
    assert CATALOGUES == {"demo": CATALOGUE, "full": FULL_CATALOGUE}
    materials = {p.material for name in FULL_CATALOGUE for p in build_scene(name, 0.3).parts}
    assert {"metal", "wood", "plastic", "cardboard", "foam"} <= materials <= set(MATERIALS)
    multi_part = [n for n in FULL_CATALOGUE if len(build_scene(n, 0.3).parts) > 1]
    assert len(multi_part) >= 6


def test_every_object_is_seen_by_the_camera_at_30_cm():
    pytest.importorskip("open3d")
    from bench.synth.camera import depth as depth_camera
    from bench.synth.config import SynthConfig

    config = SynthConfig(depth_noise=False)
    pose = depth_camera.nominal_pose(config)
    for name in FULL_CATALOGUE:
        frame = depth_camera.render(build_scene(name, 0.3), pose, config, np.random.default_rng(0))
        on_object = frame.mask == 255
        assert on_object.sum() > 500, name                                   # the thin rod: ~2,000 pixels
        rows, cols = np.nonzero(on_object)
        assert rows.min() > 0 and cols.min() > 0 and rows.max() < 479 and cols.max() < 639, name   # not cut off


def test_every_part_keeps_a_scored_ground_truth_after_maroons_smoothing():
    """The ground truth is smoothed as MAROON's is (30 Laplacian steps, realistic preset), which shrinks thin parts:
    every part at least 5 mm wide in x and y as the radar sees it keeps triangulated ground-truth pixels on the radar
    grid (what C_g, C_s and P compare with), and every object at least 300. (A shoebox wall seen edge-on, 3 mm,
    need not; 3 mm bars did vanish entirely, so the dish rack's bars are 8 mm.)"""
    pytest.importorskip("open3d")
    from bench.synth.camera.photogrammetry import smoothed_mesh
    from bench.synth.config import preset
    from bench.synth.meshes import indexed
    from bench.synth.writer import radar_grid
    from methods.domain.lattice import triangulated_vertices
    from metrics.evaluate import TRIANGULATION_THRESHOLD_M
    from metrics.groundtruth import rasterise_depth_m

    realistic, grid = preset("realistic"), radar_grid(0.30)
    for name in FULL_CATALOGUE:
        total = 0
        for part in build_scene(name, 0.30).parts:
            vertices, triangles = indexed(smoothed_mesh(part.tris_m, realistic.gt_smoothing_steps,
                                                        realistic.gt_mesh_subdivisions))
            depth_m = rasterise_depth_m(vertices, triangles, grid)
            scored = int(triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M, "maroon").sum())
            extent_m = np.ptp(part.tris_m.reshape(-1, 3)[:, :2], axis=0)
            assert scored > 0 or extent_m.min() < 5e-3, (name, part.material, extent_m)
            total += scored
        assert total >= 300, name
