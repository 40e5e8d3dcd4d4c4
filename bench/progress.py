"""Progress bars for long commands (tqdm): drawn on stderr only when it is a terminal, so logs, pipes, CI and
SLURM job files get the plain progress lines instead, and a heartbeat line at least every 30 s while a step runs
(`Heartbeat`: what runs, how far, about how long is left).

`bar` is the bar itself; `steps` and `each` also route `print` and `logging` above the bar while it is drawn
(tqdm.write), so a command's own result lines stay whole lines and the bar stays at the bottom."""
from __future__ import annotations

import codecs
import collections
import contextlib
import fcntl
import os
import pty
import shutil
import struct
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def bar(total: int | None, description: str, unit: str = "step", enabled: bool = True) -> tqdm:
    """A tqdm bar on stderr, disabled when stderr is not a terminal (`disable=None` is tqdm's own rule for that)
    or when not `enabled` (e.g. a job that runs beside others on one terminal: their bars would overwrite)."""
    return tqdm(total=total, desc=description, unit=unit, disable=None if enabled else True, file=sys.stderr,
                leave=False, dynamic_ncols=True)


class _LinesAboveBars:
    """stdout while bars are drawn on `bar_file`: whole lines only, each written with the bars cleared and redrawn
    after it (tqdm's external_write_mode), so no line starts behind a bar; a partial line waits for its newline.
    (tqdm's own DummyTqdmFile clears the bars only when the real stdout is still `sys.stdout`.)"""

    def __init__(self, stdout, bar_file):
        self._stdout, self._bar_file, self._pending = stdout, bar_file, ""

    def write(self, text: str) -> int:
        lines, newline, self._pending = (self._pending + text).rpartition("\n")
        if newline:
            with tqdm.external_write_mode(file=self._bar_file):
                self._stdout.write(lines + newline)
                self._stdout.flush()
        return len(text)

    def flush(self) -> None:
        self._stdout.flush()

    def finish(self) -> None:
        """Write what is left of a partial line (the bars are gone by then)."""
        self._stdout.write(self._pending)
        self._pending = ""
        self._stdout.flush()

    def __getattr__(self, name):             # encoding, fileno, isatty, ...: the real stdout's
        return getattr(self._stdout, name)


@contextlib.contextmanager
def steps(total: int | None, description: str, unit: str = "step", enabled: bool = True) -> Iterator[tqdm]:
    """A bar for a loop of `total` steps (call `.update()` per step); while it is drawn, stdout and logging go
    through tqdm.write above it. Off a terminal it is `bar`'s disabled bar and nothing is redirected."""
    with bar(total, description, unit, enabled) as progress:
        if progress.disable or isinstance(sys.stdout, _LinesAboveBars):   # quiet, or an outer bar redirects already
            yield progress
            return
        from tqdm.contrib.logging import logging_redirect_tqdm  # only with a bar on a terminal

        lines = _LinesAboveBars(sys.stdout, sys.stderr)
        try:
            with contextlib.redirect_stdout(lines), logging_redirect_tqdm():
                yield progress
        finally:
            lines.finish()


def each(items: Iterable[T], description: str, unit: str = "step", enabled: bool = True,
         expected_s: float | None = None) -> Iterator[T]:
    """The items, one bar step each (`steps`); the total is known when `items` has a length. Where no bar is
    drawn, a `Heartbeat` says how far the loop is at least every HEARTBEAT_S seconds (with `expected_s`, the
    seconds an item took before, an estimate from the first item on)."""
    total = len(items) if hasattr(items, "__len__") else None
    with steps(total, description, unit, enabled) as progress:
        started, done = time.perf_counter(), [0]     # (a disabled tqdm bar does not count)

        def state() -> str:
            return f"{description}: {how_far(done[0], total, unit, time.perf_counter() - started, expected_s)}"

        with Heartbeat(state) if progress.disable else contextlib.nullcontext():
            for item in items:
                yield item
                done[0] += 1
                progress.update()


HEARTBEAT_S = 30.0


def how_far(done: int, total: int | None, unit: str, elapsed_s: float, expected_s: float | None = None) -> str:
    """`3/8 frames done, 41 s, about 68 s left`: the rate so far, or before the first step the seconds a step took
    in earlier runs (`expected_s`; none known: no estimate)."""
    text = f"{done}/{total if total is not None else '?'} {unit}s done, {elapsed_s:.0f} s"
    if total is None or total <= done:
        return text
    if done:
        return f"{text}, about {elapsed_s / done * (total - done):.0f} s left"
    if expected_s is not None:
        return f"{text}, about {max(expected_s * total - elapsed_s, 0.0):.0f} s left (earlier runs)"
    return text


class Heartbeat:
    """While the `with` block runs: every `every_s` seconds a line `... <describe()>` on stderr (whole lines, so it
    mixes with logs and other jobs' lines). For steps that are silent off a terminal: a loop without a bar, a long
    merge, a report's pictures. The line comes from a thread: it appears while the work holds the CPU in NumPy,
    BLAS or a kernel (they release the interpreter lock)."""

    def __init__(self, describe: Callable[[], str], every_s: float = HEARTBEAT_S):
        self.describe, self.every_s = describe, every_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name="heartbeat", daemon=True)

    def _beat(self) -> None:
        while not self._stop.wait(self.every_s):
            print(f"... {self.describe()}", file=sys.stderr, flush=True)

    def __enter__(self) -> Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def run_relayed(command: list[str], tail_lines: int = 40, terminal: bool | None = None) -> tuple[int, list[str]]:
    """Run `command`, passing its stderr on and keeping its last `tail_lines` lines (for its error message): its
    exit code and those lines. With `terminal` (default: when stdout and stderr are both one), the command gets a
    pseudo-terminal for both, sized as ours, so its own progress bars are drawn, and what it writes is relayed to
    our stdout as it comes; otherwise its stderr is a pipe read line by line (no bars) and its stdout ours."""
    tail = collections.deque(maxlen=tail_lines)
    if terminal is None:
        terminal = sys.stdout.isatty() and sys.stderr.isatty()
    if not terminal:
        proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
        for line in proc.stderr:
            sys.stderr.write(line)
            tail.append(line.rstrip())
        return proc.wait(), list(tail)
    main_fd, sub_fd = pty.openpty()
    columns, lines = shutil.get_terminal_size()           # ours, so its bars fit (a new pty is 0 columns wide)
    fcntl.ioctl(sub_fd, termios.TIOCSWINSZ, struct.pack("HHHH", lines, columns, 0, 0))
    proc = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=sub_fd, stderr=sub_fd)
    os.close(sub_fd)
    decoder, pending = codecs.getincrementaldecoder("utf-8")(errors="replace"), ""
    try:
        while True:
            try:
                chunk = os.read(main_fd, 65536)
            except OSError:                     # EIO: the command closed the terminal
                break
            if not chunk:
                break
            text = decoder.decode(chunk)
            sys.stdout.write(text)
            sys.stdout.flush()
            *lines, pending = (pending + text).split("\n")
            tail.extend(line.rstrip("\r").split("\r")[-1].rstrip() for line in lines)   # what the screen shows
    finally:
        os.close(main_fd)
    return proc.wait(), list(tail)


def on_terminal() -> bool:
    """Whether bars are drawn (stderr is a terminal): then per-item lines go through `tqdm.write` above the bar."""
    return sys.stderr.isatty()
