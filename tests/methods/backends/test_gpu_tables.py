"""A new frame's tensor-core tables built on the device (`table_kernels`, `FrameInputs._device_tables`) equal the
host tables (`FrameInputs.host_tx_half_tables`, the specification) on fresh random frames: the gain exactly, the
fp16 operand within 1 fp16 ulp (the device rounds float64 -> float32 -> fp16; a tie may round apart)."""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.memory import ANTENNAS

from devices import CUDA


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_device_built_tx_half_tables_equal_the_host_tables(device):
    from methods.backends.warp.frames import FrameInputs

    rng = np.random.default_rng()
    for n_freqs in (2, 3):
        scale = 10.0 ** rng.uniform(-6, 3, n_freqs)                      # per-frequency levels, one all zero
        scale[rng.integers(n_freqs)] *= rng.integers(0, 2)
        shape = (len(ANTENNAS.rx_m), len(ANTENNAS.tx_m), n_freqs)
        signal = ((rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) * scale).astype(np.complex64)
        freqs_hz = np.linspace(72e9, 82e9, n_freqs)
        inputs = FrameInputs(signal, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m, "cpu"
                             if device == "warp-cpu" else "cuda:0")
        got = inputs.tx_half_tables().numpy()
        gain = inputs._device_tables()[0].numpy()
        expected = inputs.host_tx_half_tables()
        host_gain = inputs._host_mat()[0].astype(np.float32)
        assert np.array_equal(gain, host_gain)
        assert got.shape == expected.shape
        got, expected = got + np.float16(0), expected + np.float16(0)       # -0 == +0 (the host's -Si pads are -0)
        ulps = np.abs(got.view(np.int16).astype(np.int32) - expected.view(np.int16).astype(np.int32))
        assert ulps.max() <= 1 and np.mean(ulps > 0) < 1e-3, (ulps.max(), np.mean(ulps > 0))
