"""Synthetic MAROON-format captures: physically modelled MIMO radar frames, RealSense-like depth, ground truth.

Public API: `simulate_frame` (point scatterers -> frame), `generate_capture`, `generate_catalogue`,
`SynthConfig`, `CATALOGUE`. See bench/synth/README.md.
"""
from bench.synth.config import SynthConfig
from bench.synth.generate import CaptureResult, ensure_capture, generate_capture, generate_catalogue
from bench.synth.radar_model import simulate_frame
from bench.synth.scenes import CATALOGUE, build_scene

__all__ = ["CATALOGUE", "CaptureResult", "SynthConfig", "build_scene", "ensure_capture", "generate_capture",
           "generate_catalogue", "simulate_frame"]
