"""The device paths of round 3 against their CPU specifications: the Warp-rasterised MM-2FSK prior
(methods/backends/warp/prior.py vs methods/prior/priors.py), the on-device MM-2FSK depth/filter, and BP's on-device
depth
extraction (warp_backend.correlation_kernels.volume_peak_depth vs depth_peak.peak_depth_m).

Each runs on Warp's CPU device ("warp-cpu", small sizes) and on CUDA (marked `cuda`, skipped without a GPU).
Tolerances: the prior is float64 on both sides, covered sets equal up to `MAX_SILHOUETTE_PX` pixels whose centre lies
within ~1e-9 px of a triangle edge (different FMA rounding), depth within 1e-9 m (measured ~1e-16); the BP depth
from the same device volume agrees to 2e-6 m (measured <= 7e-7 m on 301x301x201: 1-ulp |V| differences, sqrt vs
hypot, through a flat dB parabola).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.synth.memory import (
    CAMERA,
    TABLE1_FREQS_HZ,
    make_capture,
    plane_depth_frame,
    plate_points_m,
    realsense2radar,
    simulate,
    square_grid,
)
from methods import reconstruct
from methods.backends import backend_for, correlate_volume
from methods.domain.capture import Mesh, RadarGrid
from methods.ops.depth_peak import peak_depth_m
from methods.prior.priors import mesh_prior_m, realsense_prior_m

from devices import CUDA

DEVICES = ["warp-cpu", CUDA]
MAX_SILHOUETTE_PX = 3
PLANE = (0.31, 0.2, -0.15)


def _compare_priors(device_prior, cpu_prior):
    gpu = np.asarray(device_prior)
    covered_gpu, covered_cpu = np.isfinite(gpu), np.isfinite(cpu_prior)
    assert device_prior.n_covered == covered_gpu.sum()
    assert (covered_gpu ^ covered_cpu).sum() <= MAX_SILHOUETTE_PX
    both = covered_gpu & covered_cpu
    assert both.sum() > 0
    assert np.max(np.abs(gpu[both] - cpu_prior[both])) < 1e-9


def _hole_scene():
    cam2radar = realsense2radar()
    rows, cols = np.mgrid[:CAMERA.height, :CAMERA.width]
    mask = (np.abs(cols - 320) < 150) & (np.abs(rows - 240) < 120) & ~((cols > 380) & (rows > 300))   # notch
    frame = plane_depth_frame(*PLANE, cam2radar, mask=mask)
    frame.depth_mm[(cols - 300) ** 2 + (rows - 220) ** 2 < 30 ** 2] = 0                             # a hole
    return frame, cam2radar


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("scene", ["plane", "plane_0.1mm", "holes", "bench_frame"])
def test_realsense_prior_on_the_device_matches_the_cpu_prior(device, scene):
    from methods.backends.warp.prior import realsense_prior
    grid = square_grid(0.15, 301)
    if scene == "holes":
        frame, cam2radar = _hole_scene()
    elif scene == "bench_frame":
        from bench.perf.frames import _full_depth_frame
        frame, cam2radar = _full_depth_frame()
    else:
        cam2radar = realsense2radar()
        frame = plane_depth_frame(*PLANE, cam2radar, 1e-4 if scene == "plane_0.1mm" else 1e-3)
    for fill in (False, True):
        device_prior = realsense_prior(backend_for(device).buffers, frame, cam2radar, grid, fill_holes=fill)
        _compare_priors(device_prior, realsense_prior_m(frame, cam2radar, grid, fill_holes=fill))
        if scene == "holes":
            assert device_prior.filled == fill          # the hull test saw the hole and the notch


@pytest.mark.parametrize("device", DEVICES)
def test_mesh_prior_on_the_device_matches_the_cpu_prior(device):
    from methods.backends.warp.prior import mesh_prior
    grid = square_grid(0.15, 301)
    vertices = np.array([[-0.05, -0.04, 0.30], [0.05, -0.04, 0.32], [0.05, 0.04, 0.32], [-0.05, 0.04, 0.30],
                         [-0.02, -0.02, 0.25], [0.02, -0.02, 0.25], [0.0, 0.03, 0.26]])
    mesh = Mesh(vertices=vertices * 1000.0, triangles=np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]]), path=Path("m"))
    to_radar = np.diag([1e-3, 1e-3, 1e-3, 1.0])
    device_prior = mesh_prior(backend_for(device).buffers, mesh, to_radar, grid)
    _compare_priors(device_prior, mesh_prior_m(mesh, to_radar, grid))
    assert np.nanmin(np.asarray(device_prior)) == pytest.approx(0.25)     # the nearer triangle wins


@pytest.mark.parametrize("device", DEVICES)
def test_device_hull_count_is_the_number_of_lattice_points_in_the_convex_hull(device):
    import warp as wp
    from scipy.spatial import Delaunay

    from methods.backends.warp.prior import FAR_M, cleared_zbuffer, coverage
    ny, nx = 30, 40
    grid = RadarGrid((0.0, 0.0, 0.2), (1.0, 1.0, 0.3), (nx, ny, 2))
    rng = np.random.default_rng(1)
    rr, cc = np.mgrid[:ny, :nx]
    for _ in range(12):
        covered = np.zeros((ny, nx), bool)
        for r, c in rng.integers(0, [ny, nx], size=(rng.integers(1, 6), 2)):
            covered[max(r - 2, 0):r + 3, max(c - 3, 0):c + 2] = True
        rows, cols = np.nonzero(covered)
        inside = Delaunay(np.column_stack([cols, rows])).find_simplex(np.column_stack([cc.ravel(), rr.ravel()]),
                                                                       tol=1e-9) >= 0
        zbuf, stats = cleared_zbuffer(backend_for(device).buffers, grid)
        zbuf.assign(np.where(covered, 0.3, FAR_M).ravel())
        assert coverage(zbuf, stats, ny, nx) == (covered.sum(), inside.sum())
        wp.synchronize()


def _tilted_plate(grid):
    points_m = plate_points_m(0.30)
    points_m[:, 2] += 0.05 * points_m[:, 0]
    cam2radar = realsense2radar()
    return make_capture(simulate(points_m, np.ones(len(points_m)), TABLE1_FREQS_HZ), TABLE1_FREQS_HZ, grid,
                        realsense=plane_depth_frame(0.30, 0.05, 0.0, cam2radar),
                        transforms={"realsense2radar": cam2radar})


@pytest.mark.parametrize("device", DEVICES)
def test_mm2fsk_frame_on_the_device_matches_the_cpu_path(device):
    from methods.api import prior_image_m
    from methods.backends.warp.prior import realsense_prior
    from methods.mm2fsk import reconstruct_mm2fsk
    grid = square_grid(0.03, 61) if device == "cuda" else square_grid(0.02, 21)
    capture = _tilted_plate(grid)
    indices = [0, 6]                                   # 72 and 82 GHz (d10)
    signal, freqs = capture.radar.signal[:, :, indices], TABLE1_FREQS_HZ[indices]
    if device == "cuda":
        rec = reconstruct(capture, "mm2fsk", "d10", prior="realsense", device="cuda")
        assert rec.device == "cuda"
    else:
        backend = backend_for(device)
        prior = realsense_prior(backend.buffers, capture.realsense, capture.transforms["realsense2radar"], grid)
        rec = reconstruct_mm2fsk(signal, freqs, capture.antennas, grid, prior, backend=backend)
    host_prior = prior_image_m(capture, "realsense", grid)
    cpu_prior = host_prior.host_m()
    ref = reconstruct_mm2fsk(signal, freqs, capture.antennas, grid, host_prior, backend=backend_for("cpu"))
    assert np.array_equal(np.isfinite(rec.extra["prior_depth_m"]), np.isfinite(cpu_prior))
    assert np.nanmax(np.abs(rec.extra["prior_depth_m"] - cpu_prior)) < 1e-9
    assert rec.extra["prior_pixels"] == ref.extra["prior_pixels"]
    assert np.array_equal(np.isfinite(rec.magnitude), np.isfinite(ref.magnitude))
    assert np.nanmax(np.abs(rec.magnitude - ref.magnitude)) < 2e-3 * np.nanmax(ref.magnitude)
    both = rec.valid & ref.valid
    assert (rec.valid ^ ref.valid).sum() <= 0.01 * ref.valid.sum() + 1   # pixels at the -14 dB threshold
    assert np.max(np.abs(rec.depth_m[both] - ref.depth_m[both])) < 5e-5   # fp16 tensor-core phasors: ~1e-5 m
    # on CUDA the whole frame is one graph (methods.backends.warp.frame_graph): its time is the 'correlate' stage
    assert {"prior", "correlate", "total"} <= set(rec.timings_ms) or device != "cuda"


@pytest.mark.parametrize("device", DEVICES)
def test_bp_depth_extraction_on_the_device_matches_the_host(device):
    from methods.backends import volume_peak_depth
    n_xy, n_z = (61, 101) if device == "cuda" else (9, 21)
    grid = RadarGrid((-0.02, -0.02, 0.25), (0.02, 0.02, 0.35), (n_xy, n_xy, n_z))
    capture = _tilted_plate(grid)
    signal, freqs = capture.radar.signal[:, :, [0, 1]], TABLE1_FREQS_HZ[[0, 1]]
    ant = capture.antennas
    y_desc = grid.y_m[::-1]
    volume = correlate_volume(signal, freqs, ant.tx_m, ant.rx_m, grid.x_m, y_desc, grid.z_m, device=device)
    ref_depth, ref_peak = peak_depth_m(np.abs(volume), float(grid.z_m[0]), float(grid.z_m[1] - grid.z_m[0]))
    depth, peak = volume_peak_depth(signal, freqs, ant.tx_m, ant.rx_m, grid.x_m, y_desc, grid.z_m, device=device)
    assert depth.shape == peak.shape == grid.image_shape
    assert np.allclose(peak, ref_peak, rtol=1e-6, atol=0)     # |V|: sqrt(re^2 + im^2) vs numpy's hypot, 1 ulp
    assert np.max(np.abs(depth - ref_depth)) < 2e-6    # 1-ulp |V| differences via the dB parabola: <= 7e-7 m
    rec = reconstruct(capture, "bp", [72.0, 74.0], device=device)          # the API path uses it
    assert np.nanmax(np.abs(rec.magnitude - ref_peak)) <= 1e-6 * ref_peak.max()
