"""Radar imaging methods (BP, 2FSK, 3FSK, MM-2FSK) on one shared correlation backend.

Entry point: `methods.reconstruct(capture, method, freq, prior="none", device="cpu", grid=None, **params)`.
"""
from methods.api import reconstruct

__all__ = ["reconstruct"]
