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
