"""The node fits (bench.synth.radar.frequency_nodes) kept on disk between runs.

A fit costs 20-200 ms (a least-squares solve and its check for every node count tried) and a catalogue needs ~45
of them (half-widths 5-140 mm): seconds of a generator run, and on a GPU the serial part of the device sums. The
fits depend only on their inputs and this machine's arithmetic, so each is kept in `$XDG_CACHE_HOME` (or
~/.cache) under mm2fsk-bench/synth-fits/, named by a hash of the inputs, the fitting code (frequency_nodes.py's
source), NumPy's version and the BLAS build and CPU kernel that computed it: a fit read back is the array this
machine computes, byte for byte (tests/bench/synth/test_synth_nodes.py). Unreadable or unwritable: computed again.
"""
from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

from bench.cachedir import default_cache_dir


def folder() -> Path | None:
    """The generator's kept fits: synth-fits in the user's cache folder; None where there is none (no HOME)."""
    base = default_cache_dir()
    return None if base is None else base / "synth-fits"


@functools.cache
def _arithmetic() -> str:
    """What decides a fit's last bits besides its inputs: NumPy's version and the BLAS libraries' build and kernel."""
    from threadpoolctl import threadpool_info

    blas = sorted(f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')}"
                  for i in threadpool_info() if i.get("user_api") == "blas")
    return f"numpy {np.__version__}; " + "; ".join(blas)


def key(source: bytes, *inputs) -> str:
    """The file name of a fit: sha256 of the fitting code's `source`, the `inputs` (repr) and the arithmetic."""
    digest = hashlib.sha256(source)
    digest.update(repr(inputs).encode() + b"\0" + _arithmetic().encode())
    return digest.hexdigest()[:32]


def load(name: str) -> tuple[np.ndarray, np.ndarray | None] | None:
    """(nodes, fit or None) kept under `name`, or None."""
    base = folder()
    if base is None:
        return None
    try:
        with np.load(base / f"{name}.npz") as kept:
            return kept["nodes"], (kept["fit"] if "fit" in kept.files else None)
    except (OSError, ValueError, KeyError):
        return None


def store(name: str, nodes: np.ndarray, fit: np.ndarray | None) -> None:
    """Keep (nodes, fit) under `name` (written whole: a temp file renamed; processes may store the same fit)."""
    base = folder()
    if base is None:
        return
    arrays = {"nodes": nodes} if fit is None else {"nodes": nodes, "fit": fit}
    tmp = None
    try:
        base.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=base, suffix=".tmp", delete=False) as handle:
            tmp = Path(handle.name)
            np.savez(handle, **arrays)
        os.replace(tmp, base / f"{name}.npz")
    except OSError:            # a read-only or full cache: computed again next time
        if tmp is not None:
            tmp.unlink(missing_ok=True)
