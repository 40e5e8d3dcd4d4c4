"""Device parameters shared by the tests: CUDA cases carry the `cuda` mark and skip where Warp sees no GPU."""
from __future__ import annotations

import pytest

from methods.backends import resolve_device


def cuda_seen() -> bool:
    """True when Warp is importable and sees a CUDA device."""
    try:
        return resolve_device("auto") == "cuda"
    except ImportError:
        return False


CUDA = pytest.param("cuda", marks=[pytest.mark.cuda, pytest.mark.skipif(not cuda_seen(),
                                                                         reason="no CUDA device seen by Warp")])
