"""FrameSamples (methods.domain.samples): a frame's samples at selected frequencies, taken or gathered."""
from __future__ import annotations

import numpy as np
import pytest

from methods.domain.samples import FrameSamples


def _frame(rng, dtype=np.complex64):
    return (rng.standard_normal((5, 4, 9)) + 1j * rng.standard_normal((5, 4, 9))).astype(dtype)


@pytest.mark.parametrize("dtype", [np.complex64, np.complex128])
def test_gathered_and_taken_samples_equal_fancy_indexing(dtype):
    rng = np.random.default_rng()
    for _ in range(20):
        frame = _frame(rng, dtype)
        indices = rng.choice(9, size=rng.integers(1, 6), replace=False)
        samples = FrameSamples(frame, indices)
        want = frame[:, :, indices]
        among = sorted(rng.choice(len(indices), size=rng.integers(1, len(indices) + 1), replace=False).tolist())
        out = np.empty(want.shape[:2] + (len(among),), dtype=np.complex64)
        samples.gather(out, among)                   # straight from the frame
        assert np.array_equal(out, want[:, :, among].astype(np.complex64)) and samples.taken is None
        assert samples.shape == want.shape and np.array_equal(np.asarray(samples), want)
        assert samples.taken.flags.c_contiguous
        samples.gather(out, among)                   # from the taken array
        assert np.array_equal(out, want[:, :, among].astype(np.complex64))


def test_every_frequency_is_the_frame_itself_and_bad_indices_are_refused():
    frame = _frame(np.random.default_rng())
    assert FrameSamples(frame).array() is frame
    for bad in ([9], [-1], [[0, 1]]):
        with pytest.raises(ValueError, match="do not select"):
            FrameSamples(frame, np.array(bad))
    with pytest.raises(ValueError, match=r"\(n_rx, n_tx, F\)"):
        FrameSamples(frame[0])
