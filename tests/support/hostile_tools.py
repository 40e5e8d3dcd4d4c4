"""Helpers of the hostile-input suite (tests/test_hostile_*.py): memory and time caps, capped subprocesses of the
real entry points, private capture copies and byte-level dataset digests.

A regression that hangs, blows up memory or crashes must fail the build, not stall it: in-process checks run under
`bounded()` (RLIMIT_AS lowered to the current address space plus a margin, and a SIGALRM timer), command lines under
`run_capped()` (RLIMIT_AS in the child and a subprocess timeout).
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import resource
import shutil
import signal
import stat
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CLI_MEMORY_BYTES = 3 << 30          # address space of one `python -m bench` (about 1.3 GiB is used on a tiny capture)
CLI_TIMEOUT_S = 90                  # one command on 2 shared cores takes 2-8 s
RADAR = "radar_72.0_82.0_16"        # the radar folder of 16-frequency synthetic captures


def _address_space_bytes() -> int:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


@contextlib.contextmanager
def bounded(seconds: float = 20.0, extra_memory_bytes: int = 1536 << 20):
    """Fail (MemoryError / TimeoutError) instead of growing past `extra_memory_bytes` or running past `seconds`."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = _address_space_bytes() + extra_memory_bytes
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)

    def expire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s (a hang?)")

    previous = signal.signal(signal.SIGALRM, expire)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _cap_child() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CLI_MEMORY_BYTES, CLI_MEMORY_BYTES))


def run_capped(args: list[str], env: dict | None = None, timeout: float = CLI_TIMEOUT_S) -> subprocess.CompletedProcess:
    """`python <args>` from the repository root, with the child's address space capped; a timeout fails the test."""
    try:
        return subprocess.run([sys.executable, *args], cwd=REPO, capture_output=True, text=True, timeout=timeout,
                              preexec_fn=_cap_child, env={**os.environ, **(env or {})})
    except subprocess.TimeoutExpired:
        pytest.fail(f"`python {' '.join(args)}` ran past {timeout} s (a hang?)")


def tree_digest(root: Path) -> dict[str, str]:
    """Every entry under `root` (links not followed): regular files by content, others by type and target."""
    digest = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            path = Path(dirpath) / name
            info = os.lstat(path)
            key = os.fsencode(path.relative_to(root)).hex()
            if stat.S_ISLNK(info.st_mode):
                digest[key] = "link:" + os.readlink(path)
            elif stat.S_ISREG(info.st_mode):
                digest[key] = hashlib.sha256(path.read_bytes()).hexdigest()
            else:
                digest[key] = f"mode:{stat.S_IFMT(info.st_mode)}"
    return digest


def copy_capture(source: Path, root: Path, object_name: str = "01_plate", distance: str = "30") -> Path:
    """A private, writable copy of the capture `source` at `root/<object_name>/<distance>`."""
    target = root / object_name / distance
    shutil.copytree(source, target)
    return target


def frame_file(capture_dir: Path) -> Path:
    return next(capture_dir.glob("radar_*/calibrated_data/000000.npy"))


def replace_with_link(path: Path, target: str | Path) -> None:
    path.unlink()
    path.symlink_to(target)


def replace_with_fifo(path: Path) -> None:
    path.unlink()
    os.mkfifo(path)


def one_error_line(stderr: str) -> str:
    """The single line of `stderr` (asserting there is exactly one, starting with `error: `)."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    return lines[0]
