"""The user's cache folder of the package, shared by every layer that keeps files between runs (the code version,
the kept ground truths, the generator's node fits)."""
from __future__ import annotations

import os
from pathlib import Path


def default_cache_dir() -> Path | None:
    """$XDG_CACHE_HOME (when absolute) or ~/.cache, then mm2fsk-bench; None where neither is known (no HOME and no
    passwd entry, as in some containers): then nothing is cached."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):
        try:
            base = Path.home() / ".cache"
        except RuntimeError:
            return None
    return Path(base) / "mm2fsk-bench"
