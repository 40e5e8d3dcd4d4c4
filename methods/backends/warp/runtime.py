"""Warp start-up: `wp.init()` once with the no-driver notice dropped, and whether a CUDA device is there."""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading

import warp as wp

NO_DRIVER_NOTICE = "Could not find or load the NVIDIA CUDA driver"


_INIT = threading.Lock()       # a sweep may start Warp on a thread of its own (bench.__main__); callers wait for it
_started: list[bool] = []


def init() -> None:
    """wp.init() once per process, whichever thread asks first (the others wait for it). Warp's native code prints a
    warning on stderr where there is no CUDA driver; on a CPU-only machine that is expected (callers ask
    `cuda_available()` and say so in one line), so that warning is dropped and anything else the native code prints
    is passed on."""
    with _INIT:
        if _started:
            return
        wp.config.log_level = wp.LOG_WARNING
        with _native_stderr() as captured:
            wp.init()
        _started.append(True)
    lines = [line for line in captured() if NO_DRIVER_NOTICE not in line]
    if lines:
        sys.stderr.write("".join(f"{line}\n" for line in lines))


@contextlib.contextmanager
def _native_stderr():
    """Capture what native code writes to file descriptor 2 (a temp file); yields a function giving its lines."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lambda: lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines.extend(tmp.read().decode(errors="replace").splitlines())


def cuda_available() -> bool:
    """True when Warp sees a CUDA device."""
    init()
    return wp.get_cuda_device_count() > 0
