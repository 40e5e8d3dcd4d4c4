"""Radar imaging methods (BP, 2FSK, 3FSK, MM-2FSK, MM-3FSK) on one correlation backend per device.

Entry point: `methods.reconstruct(capture, method, freq, prior="none", device="cpu", grid=None, **params)`.
A method of your own: subclass `methods.Method` in one file (methods/method.py says how; examples/ has one).
"""
from methods.api import reconstruct
from methods.method import Frame, Method
from methods.reconstruction import Reconstruction

__all__ = ["Frame", "Method", "Reconstruction", "reconstruct"]
