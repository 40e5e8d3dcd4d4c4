"""The pixel/voxel grid a run uses: the frame's own (faithful to MAROON) or a configured override."""
from __future__ import annotations

from collections.abc import Mapping

from bench.cli import UserError
from bench.maroon.limits import current_limits
from methods.domain.capture import Capture, RadarGrid


def grid_for(capture: Capture, override: Mapping | None) -> RadarGrid:
    """`override` None keeps the frame's calibration grid; otherwise a square x/y grid of `nxy` pixels over
    +-`xy_half_m` and `nz` depth samples over +-`z_half_m` around the capture's nominal distance (metres)."""
    if override is None:
        return capture.radar.grid
    centre_m = capture.metadata.distance_m
    half_xy, half_z = float(override["xy_half_m"]), float(override["z_half_m"])
    nxy, nz = int(override["nxy"]), int(override["nz"])
    limits = current_limits()
    if nxy < 2 or nz < 1 or nxy * nxy > limits.grid_pixels or nxy * nxy * nz > limits.grid_voxels:
        raise UserError(f"grid.override={nxy}x{nxy}x{nz}", f"must have nxy >= 2, nz >= 1 and at most "
                        f"{limits.grid_pixels:,} pixels and {limits.grid_voxels:,} voxels (BENCH_LIMITS grid_pixels, "
                        "grid_voxels)")
    if centre_m - half_z <= 0:
        raise UserError(f"grid.override.z_half_m={half_z:g}",
                        f"must be below the distance of capture {capture.name} ({centre_m:g} m): the depth window "
                        "would reach behind the radar")
    return RadarGrid(bb_min_m=(-half_xy, -half_xy, centre_m - half_z), bb_max_m=(half_xy, half_xy, centre_m + half_z),
                     size=(nxy, nxy, nz))
