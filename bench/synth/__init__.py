"""Synthetic MAROON-format captures: physically modelled MIMO radar frames, RealSense-like depth, ground truth.

Public API: `simulate_frame` (point scatterers -> frame), `generate_capture`, `generate_catalogue`,
`SynthConfig`, `CATALOGUE` (the demo's objects), `FULL_CATALOGUE`, `CATALOGUES`. See bench/synth/README.md.
"""
from bench.synth.config import SynthConfig
from bench.synth.radar.model import simulate_frame
from bench.synth.scenes import CATALOGUE, CATALOGUES, FULL_CATALOGUE, build_scene

_NEED_OPEN3D = {"CaptureResult", "ensure_capture", "generate_capture", "generate_catalogue"}

__all__ = ["CATALOGUE", "CATALOGUES", "FULL_CATALOGUE", "CaptureResult", "SynthConfig", "build_scene", "ensure_capture",
           "generate_capture", "generate_catalogue", "simulate_frame"]


def __getattr__(name: str):
    """The capture writer needs Open3D (ray casting): import it on first use, so that `simulate_frame` works on
    machines without Open3D (the GPU test machine)."""
    if name in _NEED_OPEN3D:
        from bench.synth import generate
        return getattr(generate, name)
    raise AttributeError(f"module 'bench.synth' has no attribute {name!r}")
