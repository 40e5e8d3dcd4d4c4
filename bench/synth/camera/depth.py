"""RealSense D435-like depth camera: pinhole ray casting plus an active-stereo error model.

Camera frame: OpenCV (x right, y down, z forward), metres inside this module; the stored depth is Z in uint16
millimetres. Pixel (u = column, v = row) is cast through direction ((u - cx)/fx, (v - cy)/fy, 1), so the reference
back-projection X = (u - cx) Z / fx, Y = (v - cy) Z / fy (no +0.5) recovers the hit point exactly.
Radar space (x right, y up, z forward) and the camera frame share x and z up to the tilt and differ in the sign of
y, so the camera-to-radar matrix is a reflection (determinant -1) by convention, not by error.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy import ndimage

from bench.synth.config import SynthConfig
from bench.synth.meshes import indexed, rotation_matrix
from bench.synth.scenes import Scene

WIDTH_PX, HEIGHT_PX, FPS = 640, 480, 30
WALL_HALF_SIZE_M = 1.5
WALL_COLOUR_RGB = (120, 125, 130)
MAX_MIRROR_HOP_M = 0.2     # a mirrored surface farther than this is the room, not the object (no multipath)


@dataclass(frozen=True)
class CameraPose:
    """Camera-to-radar rigid map in metres: p_radar = rotation @ p_cam + position_m."""

    rotation: np.ndarray     # (3, 3), columns = camera x, y, z axes in radar space
    position_m: np.ndarray   # (3,)
    mask_offset_px: tuple[int, int] = (0, 0)   # (rows, columns) the segmentation mask is misregistered by

    def realsense2radar(self) -> np.ndarray:
        """4x4 for camera points in millimetres -> radar metres (the 3x3 block carries the 1e-3)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation * 1e-3
        m[:3, 3] = self.position_m
        return m


@dataclass(frozen=True)
class DepthRender:
    """One rendered frame: depth_mm uint16 (0 = invalid), mask uint8 (255 = object), rgb uint8 (H, W, 3)."""

    depth_mm: np.ndarray
    mask: np.ndarray
    rgb: np.ndarray


def intrinsics(config: SynthConfig) -> dict:
    """The `rgb`/`depth` entry of realsense/calibration.json (depth is colour-aligned: identical)."""
    cx, cy = config.principal_point_px
    return {"fx": config.focal_px, "fy": config.focal_px, "cx": cx, "cy": cy, "width": WIDTH_PX,
            "height": HEIGHT_PX, "fps": FPS}


def nominal_pose(config: SynthConfig) -> CameraPose:
    """Camera at `camera_position_m` (radar space), looking along +z, pitched down by `camera_pitch_deg`."""
    a = np.deg2rad(config.camera_pitch_deg)
    z_axis = np.array([0.0, -np.sin(a), np.cos(a)])
    y_axis = np.array([0.0, -np.cos(a), -np.sin(a)])              # image down
    return CameraPose(np.column_stack([[1.0, 0.0, 0.0], y_axis, z_axis]), np.asarray(config.camera_position_m, float))


def perturbed_pose(pose: CameraPose, config: SynthConfig, rng: np.random.Generator) -> CameraPose:
    """The capture's true pose and mask registration. Calibration error: exactly `extrinsic_error_mm` /
    `extrinsic_error_deg` in random directions, or with `extrinsic_tail_dof` = nu > 2 a per-axis Student-t offset
    and rotation vector scaled so that their RMS sizes are those values (a heavy tail: some captures far off).
    Mask misregistration (`mask_errors`): `mask_shift_px` in a random direction, rounded to whole pixels."""
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    if config.extrinsic_tail_dof:
        nu = config.extrinsic_tail_dof
        unit = np.sqrt((nu - 2) / nu / 3)             # per-axis scale of a t_nu whose 3-D RMS size is 1
        rotvec_deg = rng.standard_t(nu, 3) * unit * config.extrinsic_error_deg
        offset_m = rng.standard_t(nu, 3) * unit * config.extrinsic_error_mm * 1e-3
        angle_deg = float(np.linalg.norm(rotvec_deg))
        rotation = rotation_matrix(rotvec_deg if angle_deg else axis, angle_deg) @ pose.rotation
    else:
        rotation = rotation_matrix(axis, config.extrinsic_error_deg) @ pose.rotation
        offset_m = direction / np.linalg.norm(direction) * config.extrinsic_error_mm * 1e-3
    mask_offset = (0, 0)
    if config.mask_errors and config.mask_shift_px:
        angle = rng.uniform(0.0, 2.0 * np.pi)
        mask_offset = tuple(int(v) for v in np.rint(config.mask_shift_px * np.array([np.sin(angle), np.cos(angle)])))
    return CameraPose(rotation, pose.position_m + offset_m, mask_offset)


def _wall(config: SynthConfig) -> np.ndarray:
    s, z = WALL_HALF_SIZE_M, config.wall_distance_m
    corners = np.array([[-s, -s, z], [s, -s, z], [s, s, z], [-s, s, z]])
    return np.stack([corners[[0, 2, 1]], corners[[0, 3, 2]]])     # normal towards -z (the sensors)


def _cast(scene: Scene, pose: CameraPose, config: SynthConfig):
    """Ray-cast every pixel: Z (m, inf = no hit), cos(incidence), geometry index (-1 none, len(parts) = wall) and
    the rays (`Rays`) for the effects that trace on."""
    geometries = [p.tris_m for p in scene.parts] + ([_wall(config)] if config.background_wall else [])
    raycaster = o3d.t.geometry.RaycastingScene()
    for tris in geometries:
        vertices, triangles = indexed(tris)
        raycaster.add_triangles(vertices.astype(np.float32), triangles.astype(np.uint32))
    cx, cy = config.principal_point_px
    v, u = np.mgrid[0:HEIGHT_PX, 0:WIDTH_PX].astype(np.float64)
    dirs_cam = np.stack([(u - cx) / config.focal_px, (v - cy) / config.focal_px, np.ones_like(u)], -1)
    dirs_radar = dirs_cam @ pose.rotation.T
    rays = np.concatenate([np.broadcast_to(pose.position_m, dirs_radar.shape), dirs_radar], -1)
    hit = raycaster.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6).astype(np.float32)))
    z_m = hit["t_hit"].numpy().reshape(HEIGHT_PX, WIDTH_PX).astype(np.float64)   # |dir_cam.z| = 1 -> t = Z
    geometry = hit["geometry_ids"].numpy().astype(np.int64).reshape(HEIGHT_PX, WIDTH_PX)
    geometry[~np.isfinite(z_m)] = -1
    normals = hit["primitive_normals"].numpy().reshape(HEIGHT_PX, WIDTH_PX, 3).astype(np.float64)
    cos_inc = np.abs(np.einsum("hwk,hwk->hw", normals, dirs_radar)) / np.linalg.norm(dirs_radar, axis=-1)
    return z_m, cos_inc, geometry, Rays(pose.position_m, dirs_radar, normals, raycaster)


@dataclass(frozen=True)
class Rays:
    """What the ray cast saw, for the effects that trace on: origin (3,) m, directions (H, W, 3) with unit camera z
    (so t = Z), surface normals (H, W, 3) and the scene it was cast into."""

    origin_m: np.ndarray
    dirs: np.ndarray
    normals: np.ndarray
    raycaster: object


def _stereo_errors(z_m: np.ndarray, cos_inc: np.ndarray, config: SynthConfig, rng: np.random.Generator):
    """Noisy Z in metres with NaN holes: disparity noise, steep slopes, depth edges, random dropouts."""
    valid = np.isfinite(z_m)
    z = np.where(valid, z_m, np.nan)
    if not config.depth_noise:
        return z
    focal_px = config.depth_focal_px or config.focal_px
    sigma_m = z ** 2 * config.disparity_sigma_px / (focal_px * config.stereo_baseline_m)
    if config.noise_angle_exponent:         # the pattern is stretched and the window spans more depth when slanted
        sigma_m = sigma_m / np.clip(cos_inc, 0.2, 1.0) ** config.noise_angle_exponent
    z = z + rng.normal(size=z.shape) * np.nan_to_num(sigma_m)
    holes = cos_inc < np.cos(np.deg2rad(config.max_incidence_deg))
    filled = np.where(valid, z_m, 1e3)
    jump = np.zeros_like(valid)
    for axis in (0, 1):
        step = np.abs(np.diff(filled, axis=axis)) > config.edge_jump_m
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 0)
        jump |= np.pad(step, pad) | np.pad(step, [(b, a) for a, b in pad])
    if config.edge_fattening_px > 0:
        z = _edge_pixels(z, filled, jump, config, rng)
        jump = np.zeros_like(jump)                  # the band is handled there: mixed, fattened or lost
    elif config.edge_hole_px > 0:
        jump = ndimage.binary_dilation(jump, iterations=config.edge_hole_px)
    holes |= jump | (rng.random(z.shape) < config.dropout_fraction)
    z[holes] = np.nan
    return z


def _edge_pixels(z: np.ndarray, filled_m: np.ndarray, jump: np.ndarray, config: SynthConfig,
                 rng: np.random.Generator) -> np.ndarray:
    """Active stereo at depth edges: the correlation window straddles both surfaces, so within `edge_fattening_px`
    of an edge a pixel takes the nearer surface's depth (foreground fattening, the usual block-matching artefact),
    a depth between the two (`flying_pixel_fraction`: mixed or "flying" pixels), or none (30 %: left-right check)."""
    size = 2 * config.edge_fattening_px + 1
    band = ndimage.binary_dilation(jump, iterations=config.edge_fattening_px)
    near_m = ndimage.minimum_filter(filled_m, size=size)
    far_m = np.minimum(ndimage.maximum_filter(filled_m, size=size), 10.0)
    draw = rng.random(z.shape)
    flying = band & (draw < config.flying_pixel_fraction)
    lost = band & (draw >= config.flying_pixel_fraction) & (draw < config.flying_pixel_fraction + 0.3)
    fattened = band & ~flying & ~lost
    out = z.copy()
    if config.edge_ramp:
        # the correlation window averages both surfaces: across the band the depth runs as the window's mean, a
        # ramp of (far - near) / size per pixel, which a 10 mm jump rule keeps wherever the gap is < size x 10 mm
        ramp_m = ndimage.uniform_filter(np.minimum(filled_m, 10.0), size=size)
        mixed = band & ~lost
        out[mixed] = ramp_m[mixed] + (z - filled_m)[mixed].clip(-0.01, 0.01)
    else:
        out[flying] = (near_m + rng.random(z.shape) * (far_m - near_m))[flying]
        out[fattened] = near_m[fattened] + (z - filled_m)[fattened].clip(-0.01, 0.01)   # keeps the pixel's noise
    out[lost] = np.nan
    return out


def _slant_and_material_errors(z: np.ndarray, cos_inc: np.ndarray, geometry: np.ndarray, scene: Scene,
                               config: SynthConfig, rng: np.random.Generator) -> np.ndarray:
    """Depth scale error, bias on slanted surfaces and the errors of each part's material (bench.synth.materials)."""
    from bench.synth.materials import MATERIALS

    z = z * (1.0 + config.depth_scale_error)          # the device's absolute (scale) error
    if config.slant_bias_px:
        tan_inc = np.sqrt(1.0 - np.clip(cos_inc, 0.2, 1.0) ** 2) / np.clip(cos_inc, 0.2, 1.0)
        z += z ** 2 * config.slant_bias_px * tan_inc / (config.focal_px * config.stereo_baseline_m)
    if config.camera_materials:
        draw = rng.random(z.shape)
        for index, part in enumerate(scene.parts):
            material = MATERIALS[part.material]
            on_part = geometry == index
            z[on_part] += material.subsurface_bias_m                   # translucent: the match lies below the surface
            # per-pixel stand-ins for the mirrored and saturated pattern, unless traced (ir_multipath, camera_holes)
            outlier_share = 0.0 if config.ir_multipath else material.outlier_fraction
            dropout_share = 0.0 if config.camera_holes else material.dropout_fraction
            outlier = on_part & (draw < outlier_share)
            z[outlier] += rng.uniform(0.02, 0.06, int(outlier.sum()))   # a mirrored surface, farther away
            dropped = on_part & (draw >= outlier_share) & (draw < outlier_share + dropout_share)
            z[dropped] = np.nan
    return z


def _shade(z_m: np.ndarray, cos_inc: np.ndarray, geometry: np.ndarray, scene: Scene) -> np.ndarray:
    """Simple headlight shading: albedo * (0.25 + 0.75 cos(incidence)); black where nothing is hit."""
    palette = np.array([p.colour_rgb for p in scene.parts] + [WALL_COLOUR_RGB, (0, 0, 0)], dtype=np.float64)
    albedo = palette[np.where(geometry < 0, len(palette) - 1, geometry)]
    light = np.where(np.isfinite(z_m), 0.25 + 0.75 * cos_inc, 0.0)
    return np.clip(albedo * light[..., None], 0, 255).astype(np.uint8)


def _mirrored_depth(z_m: np.ndarray, geometry: np.ndarray, rays: Rays, scene: Scene) -> np.ndarray:
    """IR multipath: where a surface with `ir_mirror` > 0 mirrors another part of the scene (a concave object), the
    camera sees that part's projected pattern behind the mirror, at depth Z + hop x (ray's z); the match follows it
    with weight `ir_mirror` (metal 1: the virtual image; glossy plastic: a partial pull). Z unchanged elsewhere."""
    import open3d as o3d

    from bench.synth.materials import MATERIALS

    weight = np.array([MATERIALS[p.material].ir_mirror for p in scene.parts] + [0.0, 0.0])
    w = weight[np.where(geometry < 0, len(weight) - 1, geometry)]
    v, u = np.nonzero((w > 0) & np.isfinite(z_m))
    if not len(v):
        return z_m
    dirs = rays.dirs[v, u] / np.linalg.norm(rays.dirs[v, u], axis=1, keepdims=True)   # unit; camera z of 1 per t
    normals = rays.normals[v, u]
    normals = normals * -np.sign(np.einsum("ij,ij->i", normals, dirs))[:, None]     # towards the camera
    reflected = dirs - 2.0 * np.einsum("ij,ij->i", dirs, normals)[:, None] * normals
    start = rays.origin_m + rays.dirs[v, u] * z_m[v, u, None] + 1e-4 * normals
    hit = rays.raycaster.cast_rays(o3d.core.Tensor(np.concatenate([start, reflected], 1).astype(np.float32)))
    hop_m = hit["t_hit"].numpy().astype(np.float64)
    target = hit["geometry_ids"].numpy().astype(np.int64)
    mirrors = np.isfinite(hop_m) & (hop_m < MAX_MIRROR_HOP_M) & (target < len(scene.parts))
    v, u, hop_m = v[mirrors], u[mirrors], hop_m[mirrors]
    out = z_m.copy()
    out[v, u] += w[v, u] * hop_m / np.linalg.norm(rays.dirs[v, u], axis=1)   # the virtual image's camera Z
    return out


def _contiguous_holes(z: np.ndarray, z_true_m: np.ndarray, cos_inc: np.ndarray, geometry: np.ndarray, scene: Scene,
                      config: SynthConfig, rng: np.random.Generator) -> np.ndarray:
    """Holes in blobs rather than single pixels: a smooth random field (correlation `hole_correlation_px`) shapes
    (a) the specular highlight, where the surface turns within `highlight_deg` of the mirror direction of the
    projector (beside the camera) and the pattern saturates the sensor, and (b) dark parts, whose infrared return
    albedo cos(inc) (0.3 m / Z)^2 falls below `ir_return_floor`."""
    from bench.synth.materials import MATERIALS

    field = ndimage.gaussian_filter(rng.normal(size=z.shape), config.hole_correlation_px)
    field /= max(float(field.std()), 1e-12)
    incidence_deg = np.degrees(np.arccos(np.clip(cos_inc, 0.0, 1.0)))
    out = z.copy()
    for index, part in enumerate(scene.parts):
        material = MATERIALS[part.material]
        on_part = geometry == index
        highlight = incidence_deg < material.highlight_deg * (1.0 + 0.3 * field)
        ir_return = material.ir_albedo * cos_inc * (0.3 / np.where(on_part, z_true_m, 1.0)) ** 2
        dark = ir_return * np.exp(0.5 * field) < config.ir_return_floor
        out[on_part & (highlight | dark)] = np.nan
    return out


def segmentation_mask(geometry: np.ndarray, scene: Scene, pose: CameraPose, config: SynthConfig) -> np.ndarray:
    """Object mask (bool) as a segmenter draws it on the colour image (`mask_errors`): pulled in by
    `mask_erosion_px` along the outline of dark or shiny parts, spread `mask_bleed_px` onto the background and
    misregistered by the capture's `mask_offset_px`. Pixel-exact (the ray cast's object pixels) when off."""
    from bench.synth.materials import MATERIALS

    parts = [i for i, part in enumerate(scene.parts) if part.ground_truth]
    exact = np.isin(geometry, parts)
    if not config.mask_errors:
        return exact
    mask = exact.copy()
    for index in parts:
        erosion_px = MATERIALS[scene.parts[index].material].mask_erosion_px
        if erosion_px:
            rim = exact & ~ndimage.binary_erosion(exact, iterations=erosion_px)
            mask &= ~(rim & (geometry == index))
    if config.mask_bleed_px:
        mask = ndimage.binary_dilation(mask, iterations=config.mask_bleed_px)
    rows, cols = pose.mask_offset_px
    return ndimage.shift(mask, (rows, cols), order=0, mode="constant", cval=False)


def render(scene: Scene, pose: CameraPose, config: SynthConfig, rng: np.random.Generator) -> DepthRender:
    """Depth (uint16 mm, 0 = invalid), object mask and RGB of `scene` seen from `pose` (the true pose)."""
    z_m, cos_inc, geometry, rays = _cast(scene, pose, config)
    seen_m = _mirrored_depth(z_m, geometry, rays, scene) if config.ir_multipath else z_m
    noisy_m = _stereo_errors(seen_m, cos_inc, config, rng)
    if config.slant_bias_px or config.camera_materials or config.depth_scale_error:
        noisy_m = _slant_and_material_errors(noisy_m, cos_inc, geometry, scene, config, rng)
    if config.camera_holes:
        noisy_m = _contiguous_holes(noisy_m, z_m, cos_inc, geometry, scene, config, rng)
    if config.min_depth_m:
        noisy_m = np.where(noisy_m < config.min_depth_m, np.nan, noisy_m)   # nearer than the disparity search reaches
    depth_mm = np.where(np.isfinite(noisy_m), np.rint(noisy_m * 1000.0), 0)
    depth_mm = np.clip(depth_mm, 0, 65535).astype(np.uint16)
    mask = np.where(segmentation_mask(geometry, scene, pose, config), 255, 0).astype(np.uint8)
    return DepthRender(depth_mm, mask, _shade(z_m, cos_inc, geometry, scene))
