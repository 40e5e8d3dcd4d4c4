"""What this process may use of the machine it runs on."""
from __future__ import annotations

import os


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity, not `os.cpu_count()`, which counts the host's every
    core, e.g. the whole machine under a container limited to a few of them (a thread started per host core there
    only waits for its turn)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
