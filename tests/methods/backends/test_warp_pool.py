"""The Warp backend's pool of device buffers (methods.backends.warp.frames.BufferPool), on Warp's CPU device."""
from __future__ import annotations


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
