"""bench.perf.skips.gpu: frames no cache has seen (same physics), the agreement share, the one-line CLI error."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from bench.perf.skips.gpu import agreement, new_frame
from bench.synth.memory import make_capture, square_grid
from methods.domain.capture import CameraIntrinsics, DepthFrame

ROOT = Path(__file__).resolve().parents[3]


def test_new_frame_rotates_the_phase_and_shifts_the_depth_only():
    rng = np.random.default_rng()
    signal = (rng.standard_normal((94, 94, 2)) + 1j * rng.standard_normal((94, 94, 2))).astype(np.complex64)
    depth_mm = rng.integers(0, 600, (48, 64)).astype(np.uint16)
    realsense = DepthFrame(index=0, depth_mm=depth_mm, mask=None, depth_scale_m=0.001, path=Path("memory"),
                           intrinsics=CameraIntrinsics(fx=60.0, fy=60.0, cx=32.0, cy=24.0, width=64, height=48))
    capture = make_capture(signal, np.array([76e9, 77e9]), square_grid(0.02, 5), realsense=realsense)
    frame = new_frame(capture, rng, 1)
    ratio = frame.radar.signal / signal
    assert np.allclose(np.abs(ratio), 1.0, atol=1e-5) and np.allclose(ratio, ratio.flat[0], atol=1e-5)
    moved = frame.realsense.depth_mm.astype(int) - depth_mm.astype(int)
    assert np.array_equal(moved, np.where(depth_mm > 0, 1, 0))
    assert capture.radar.signal is signal and capture.realsense.depth_mm is depth_mm      # the input is untouched


def test_agreement_counts_pixels_within_a_tenth_of_a_millimetre_and_a_lost_or_gained_one_as_wrong():
    ref = np.array([0.30, 0.31, np.nan, 0.33])
    assert agreement(ref, np.array([0.30005, 0.3102, 0.5, np.nan])) == 25.0   # 1 of 4: a miss, a gain, a loss
    assert agreement(ref, np.full(4, np.nan)) == 0.0
    assert agreement(np.full(4, np.nan), np.full(4, np.nan)) == 100.0


def test_unknown_case_is_one_error_line():
    out = subprocess.run([sys.executable, "-m", "bench.perf", "skips-gpu", "--root", str(ROOT), "--cases", "bp_x"],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and out.stderr.strip().splitlines() == [
        "error: --cases: unknown case(s) bp_x; choose from bp_full, bp_d05, mm2fsk_d10, 2fsk_d05, 3fsk_d05_d10"]
