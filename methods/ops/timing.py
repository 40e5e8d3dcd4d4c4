"""Per-stage wall-clock timing of a reconstruction (milliseconds)."""
from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager


class StageTimer:
    """Accumulates wall time per named stage; `total` is the time since construction (or `start`)."""

    def __init__(self) -> None:
        self.ms: dict[str, float] = {}
        self._start = time.perf_counter()

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the enclosed block and add it to stage `name` (stages may repeat, e.g. two correlation passes)."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.ms[name] = self.ms.get(name, 0.0) + 1e3 * (time.perf_counter() - t0)

    def finish(self) -> dict[str, float]:
        """The stage times plus `total` (ms), which includes any untimed glue between stages."""
        return {**self.ms, "total": 1e3 * (time.perf_counter() - self._start)}
