"""Radar imaging methods (BP, 2FSK, 3FSK, MM-2FSK, MM-3FSK) on one correlation backend per device.

Entry point: `methods.reconstruct(capture, method, freq, prior="none", device="cpu", grid=None, **params)`.
A method of your own: subclass `methods.Method` in one file (methods/method.py says how; examples/ has one).
The names below load on first use, so that `methods.domain` (the types every floor stands on) imports alone.
"""
from __future__ import annotations

import importlib

_EXPORTS = {"reconstruct": "methods.api", "Frame": "methods.method", "Method": "methods.method",
            "Reconstruction": "methods.reconstruction"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'methods' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name]), name)
