"""The Warp backend's pool of device buffers and its frame cache (methods.backends.warp.frames): the pool on Warp's
CPU device, the frame cache's pinned staging on CUDA."""
from __future__ import annotations

import pytest

from devices import CUDA


def test_the_pool_keeps_the_constants_of_the_last_grids_only():
    """Each capture's ROI makes its own search grid: a long sweep must not keep every grid's device arrays, and a
    grid still in use is not built again."""
    from methods.backends.warp.frames import BufferPool

    pool, built = BufferPool("cpu"), []
    kept = BufferPool.CONSTANTS_KEPT
    for grid in range(kept + 5):
        pool.constant(("grid", grid), lambda grid=grid: built.append(grid) or grid)
    for grid in range(5, kept + 5):                                   # the last CONSTANTS_KEPT: all kept
        assert pool.constant(("grid", grid), lambda: built.append("again")) == grid
    assert "again" not in built
    assert pool.constant(("grid", 0), lambda: built.append(0) or 0) == 0 and built.count(0) == 2   # dropped: rebuilt


def test_a_flat_staging_buffer_only_grows():
    """Sizes that change from call to call (each capture's ROI) reuse the largest buffer asked for so far."""
    import warp as wp

    from methods.backends.warp.frames import BufferPool

    pool = BufferPool("cpu")
    first = pool.pinned_flat(10, wp.float64, "maps")
    assert first.shape == (10,) and pool.pinned_flat(4, wp.float64, "maps") is first
    grown = pool.pinned_flat(25, wp.float64, "maps")
    assert grown.shape == (25,) and pool.pinned_flat(10, wp.float64, "maps") is grown
    assert pool.pinned_flat(10, wp.int32, "maps").dtype == wp.int32          # another dtype: its own buffer


@pytest.mark.parametrize("device", [CUDA])
def test_recycled_staging_buffers_keep_every_frame_its_own_samples(device, monkeypatch):
    """On CUDA each new frame is copied into a pinned buffer recycled from evicted frames and uploaded from there:
    more frames than the cache holds, then the first again, give each frame's own correlation (the same values as
    when it was new), and with the device check on (CHECK_BYTES lowered) a NaN frame among them is refused."""
    import numpy as np

    from methods.backends import backend_for
    from methods.backends.warp.frames import FRAME_CACHE_SIZE, FrameCache
    from methods.domain.errors import NonFiniteSignal

    monkeypatch.setattr(FrameCache, "CHECK_BYTES", 0)
    backend = backend_for(device)
    rng = np.random.default_rng(5)
    tx_m, rx_m = rng.uniform(-0.07, 0.07, (12, 3)), rng.uniform(-0.07, 0.07, (10, 3))
    tx_m[:, 2] = rx_m[:, 2] = 0.0
    freqs_hz = np.array([77e9, 79e9])
    points_m = np.column_stack([rng.uniform(-0.05, 0.05, (40, 2)), rng.uniform(0.25, 0.35, 40)])
    frames = [(rng.standard_normal((10, 12, 2)) + 1j * rng.standard_normal((10, 12, 2))).astype(np.complex64)
              for _ in range(FRAME_CACHE_SIZE + 3)]
    first = [backend.correlate(f, freqs_hz, tx_m, rx_m, points_m) for f in frames]
    again = [backend.correlate(f.copy(), freqs_hz, tx_m, rx_m, points_m) for f in frames[::-1]][::-1]
    for a, b in zip(first, again, strict=True):
        assert np.array_equal(a, b)
    assert not np.array_equal(first[0], first[1])
    bad = frames[2].copy()
    bad[1, 2, 0] = np.inf
    with pytest.raises(NonFiniteSignal):
        backend.correlate(bad, freqs_hz, tx_m, rx_m, points_m)
    assert np.array_equal(backend.correlate(frames[3].copy(), freqs_hz, tx_m, rx_m, points_m), first[3])
