"""A radar frame's samples at a configuration's frequencies, taken from the frame only when first asked for: a backend
that stages the samples in its own buffer gathers them there straight from the frame (`FrameSamples.gather`), so a
fresh frame's memory is read once (the take into a new array and the copy into the staging buffer cost ~0.13 ms of
an MM-2FSK call on the H100's host; the gather alone ~0.07 ms)."""
from __future__ import annotations

import numpy as np


class FrameSamples:
    """The samples (n_rx, n_tx, F) of `frame` (n_rx, n_tx, F_all) at the frequency `indices` (None: every one).

    `array()` is them as an array (taken once; the frame itself when every frequency is selected); numpy functions
    take that array too (`__array__`). `checked` is set by a backend that checked them for NaN/Inf on its device and
    found them finite (methods.api then skips the host's check)."""

    def __init__(self, frame: np.ndarray, indices: np.ndarray | None = None):
        frame = np.asarray(frame)
        if frame.ndim != 3:
            raise ValueError(f"a radar frame's samples are (n_rx, n_tx, F), got shape {frame.shape}")
        if indices is not None:
            indices = np.asarray(indices, dtype=np.intp)
            listed = indices.tolist()               # (a few: Python's min/max beat two NumPy reductions)
            if indices.ndim != 1 or (listed and (min(listed) < 0 or max(listed) >= frame.shape[2])):
                raise ValueError(f"frequency indices {indices} do not select among the frame's {frame.shape[2]}")
        self.frame, self.indices = frame, indices
        self.shape = frame.shape[:2] + (frame.shape[2] if indices is None else len(indices),)
        self.dtype = frame.dtype
        self.checked = False
        self._array: np.ndarray | None = None

    def array(self) -> np.ndarray:
        """The samples (n_rx, n_tx, F), C-contiguous: the frame itself for every frequency, else a new array made
        on the first call (np.take: ~3x faster than fancy indexing)."""
        if self._array is None:
            self._array = (np.ascontiguousarray(self.frame) if self.indices is None
                           else np.take(self.frame, self.indices, axis=2))
        return self._array

    @property
    def taken(self) -> np.ndarray | None:
        """`array()` if it was made, else None."""
        return self._array

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        array = self.array()
        return array if dtype is None else array.astype(dtype, copy=bool(copy))

    def gather(self, out: np.ndarray, among: list[int] | None = None) -> None:
        """Write the samples into `out` (n_rx, n_tx, F'), with `among` those at these positions of the selected
        frequencies: straight from the frame where `array()` was not made (one pass over it), else from that."""
        source, indices = (self.frame, self.indices) if self._array is None else (self._array, None)
        if among is not None:
            indices = np.asarray(among) if indices is None else indices[among]
        if indices is None:
            np.copyto(out, source, casting="same_kind")
        elif source.dtype == out.dtype:     # (indices checked at construction: clip is the take without its checks)
            np.take(source, indices, axis=2, out=out, mode="clip")
        else:
            np.copyto(out, source[:, :, indices], casting="same_kind")
