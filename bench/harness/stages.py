"""Where a sweep's wall time goes: seconds per stage (composition, imports, reading, ground truth, methods,
metrics, outputs, merge), for `python -m bench.perf experiment`.

Off unless the environment names a file (`BENCH_STAGES_FILE`): then `python -m bench` counts, each second going to
the innermost stage open on the main thread (an import inside a reading counts as imports), and writes
`{"stages_s": {...}, "process_s": ..., "background_s": {...}}` there when it exits. Work on a background thread
(outputs written while the next cell runs) is summed apart in `background_s`: it overlaps the main thread's
stages. Standard library only: it is imported before Hydra, to count Hydra's imports too.
"""
from __future__ import annotations

import atexit
import builtins
import collections
import contextlib
import json
import os
import sys
import threading
import time

ENV = "BENCH_STAGES_FILE"
_seconds: collections.Counter = collections.Counter()
_background: collections.Counter = collections.Counter()
_stack: list[list] = []                   # [name, started] of the open stages, innermost last
_lock = threading.Lock()
_on = False
_clock = time.perf_counter
_started = _clock()


def enabled() -> bool:
    return _on


def begin(name: str) -> None:
    """Open stage `name` on the main thread (the stage it interrupts stops counting until `end`)."""
    if not _on:
        return
    now = _clock()
    if _stack:
        _seconds[_stack[-1][0]] += now - _stack[-1][1]
    _stack.append([name, now])


def end() -> None:
    """Close the innermost open stage; the one it interrupted counts again."""
    if not _on or not _stack:
        return
    now = _clock()
    name, started = _stack.pop()
    _seconds[name] += now - started
    if _stack:
        _stack[-1][1] = now


@contextlib.contextmanager
def stage(name: str):
    """`with stage('reading'):` on the main thread; on another thread the time is summed in `background_s`."""
    if not _on:
        yield
        return
    if threading.current_thread() is not threading.main_thread():
        started = time.perf_counter()
        try:
            yield
        finally:
            with _lock:
                _background[name] += time.perf_counter() - started
        return
    begin(name)
    try:
        yield
    finally:
        end()


def add_background(name: str, seconds: float) -> None:
    """Seconds of stage `name` spent elsewhere (a worker process, bench.harness.workers), summed in `background_s`."""
    if _on and seconds:
        with _lock:
            _background[name] += seconds


def _timed_import(original):
    def __import__(name, globals=None, locals=None, fromlist=(), level=0):
        loaded = level == 0 and name in sys.modules and all(hasattr(sys.modules[name], f) for f in fromlist or ())
        nested = _stack and _stack[-1][0] == "imports"
        if loaded or nested or threading.current_thread() is not threading.main_thread():
            return original(name, globals, locals, fromlist, level)
        begin("imports")
        try:
            return original(name, globals, locals, fromlist, level)
        finally:
            end()
    return __import__


def _write(path: str) -> None:
    while _stack:
        end()
    report = {"stages_s": dict(_seconds), "background_s": dict(_background),
              "process_s": time.perf_counter() - _started}
    with open(path, "w") as handle:
        json.dump(report, handle, indent=1)


def start_from_environment() -> None:
    """Count stages when `BENCH_STAGES_FILE` is set (imports through `builtins.__import__`); written at exit."""
    global _on
    path = os.environ.get(ENV)
    if not path or _on:
        return
    _on = True
    builtins.__import__ = _timed_import(builtins.__import__)
    atexit.register(_write, path)
