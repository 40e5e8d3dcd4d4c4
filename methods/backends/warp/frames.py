"""What a Warp backend keeps on its device between calls: one frame's inputs in each kernel's layout (cached by
content), what depends on the antennas or the frequencies only (kept across frames), and a pool of reusable work
buffers. On CUDA a new frame uploads its raw samples once and builds the tensor-core tables on the device
(`table_kernels`); Warp-CPU builds them on the host (the reference the tests compare with)."""
from __future__ import annotations

import weakref
from collections import OrderedDict
from contextlib import contextmanager
from functools import cached_property

import numpy as np
import warp as wp

from methods.backends.warp.kernels import tables as table_kernels
from methods.backends.warp.kernels.correlation import MAX_ANTENNAS, TC2_HALF, TC2_KP, TC2_PAD, TC_ANT, TX_CHUNK
from methods.domain.errors import NonFiniteSignal
from methods.domain.radar import C_M_PER_S
from methods.ops import range_compression

FRAME_CACHE_SIZE = 4
CONSTANTS_KEPT = 16            # antenna / frequency layouts kept (a sweep uses one array and a few configurations)
_CONSTANTS: dict = {}


def _constant(key, build):
    """The arrays `build()` made for `key` (device, kind and the exact bytes they derive from), built once."""
    if key not in _CONSTANTS:
        _CONSTANTS[key] = build()
        while len(_CONSTANTS) > CONSTANTS_KEPT:
            _CONSTANTS.pop(next(iter(_CONSTANTS)))
    return _CONSTANTS[key]


def vec2_of(a: np.ndarray) -> np.ndarray:
    """complex array -> float32 (..., 2) for wp.vec2f arrays."""
    return np.stack([a.real, a.imag], axis=-1).astype(np.float32)


def antennas4(ant_m: np.ndarray, n: int) -> np.ndarray:
    """(n, 4) float32 rows (x, y, z, |q|^2), padded by repeating the last antenna."""
    q = np.pad(ant_m, ((0, n - len(ant_m)), (0, 0)), mode="edge").astype(np.float32)
    return np.column_stack([q, np.einsum("ai,ai->a", q, q)]).astype(np.float32)


class FrameInputs:
    """Device copies of one frame's antenna positions, wavenumbers and normalised signal (F, R, T).

    Cached per frame (`FrameCache`); the padded/fp16 layouts of each kernel are built on first use.
    """

    def __init__(self, signal, freqs_hz, tx_m, rx_m, wp_device: str):
        if len(tx_m) > MAX_ANTENNAS or len(rx_m) > MAX_ANTENNAS:
            raise ValueError(f"Warp kernels hold at most {MAX_ANTENNAS} antennas per side")
        self.device = wp_device
        self.freqs_hz, self.tx_m, self.rx_m = freqs_hz, tx_m, rx_m
        self.raw = signal                                                      # (R, T, F) complex64, host
        self.scale = 1.0 / (len(rx_m) * len(tx_m))
        self.n_freqs = len(freqs_hz)
        self._antenna_key = (wp_device, tx_m.tobytes(), rx_m.tobytes())
        self.tx, self.rx = _constant(self._antenna_key + ("vec3",), lambda: (
            wp.array(tx_m.astype(np.float32), dtype=wp.vec3f, device=wp_device),
            wp.array(rx_m.astype(np.float32), dtype=wp.vec3f, device=wp_device)))
        self.k, self.cycles = _constant((wp_device, "freqs", np.asarray(freqs_hz).tobytes()), lambda: (
            wp.array((2 * np.pi * freqs_hz / C_M_PER_S).astype(np.float32), dtype=wp.float32, device=wp_device),
            wp.array(2.0 * freqs_hz / C_M_PER_S, dtype=wp.float64, device=wp_device)))
        self._layouts = {}

    @cached_property
    def sig(self) -> np.ndarray:
        """(F, R, T) normalised samples on the host (the layouts built on the host start from it)."""
        return np.ascontiguousarray(np.moveaxis(self.raw, 2, 0)) * self.scale

    @property
    def raw_device(self) -> wp.array:
        """The raw frame (R, T, F) vec2f on the device: one upload (`upload`, where the cache staged the frame)."""
        return self._get("raw", lambda: wp.array(
            np.ascontiguousarray(self.raw, dtype=np.complex64).view(np.float32).reshape(*self.raw.shape, 2),
            dtype=wp.vec2f, device=self.device))

    def stage(self, signal: np.ndarray, staged: wp.array, chunks: int = 4) -> None:
        """`raw_device` from the complex64 frame `signal` (R, T, F) through `staged`, a pinned host buffer (R, T, F)
        vec2f that then holds a copy of it: the host copies `chunks` slabs of rows one after the other, each uploaded
        asynchronously as soon as it is staged, so the uploads overlap the host's copying (a 9 MB frame from
        pageable memory cost ~1 ms of the host's time on the H100, besides the copy)."""
        raw = wp.empty(staged.shape, dtype=wp.vec2f, device=self.device)
        host = staged.numpy().view(np.complex64)[..., 0]
        per_row = int(np.prod(signal.shape[1:]))
        bounds = np.linspace(0, signal.shape[0], min(chunks, signal.shape[0]) + 1).astype(int)
        for r0, r1 in zip(bounds[:-1], bounds[1:], strict=True):
            np.copyto(host[r0:r1], signal[r0:r1])
            wp.copy(raw, staged, dest_offset=r0 * per_row, src_offset=r0 * per_row, count=(r1 - r0) * per_row)
        self._layouts["raw"] = raw

    def samples_finite(self) -> bool:
        """Whether every sample of `raw_device` is finite: one kernel and a 4-byte copy back (the host's check of a
        9 MB frame, a sum, cost ~1 ms on the H100's host)."""
        flag = wp.zeros(1, dtype=wp.int32, device=self.device)
        raw = self.raw_device
        wp.launch(table_kernels.flag_nonfinite, dim=raw.shape, inputs=[raw, flag], device=self.device)
        return not int(flag.numpy()[0])

    def _get(self, name, build):
        if name not in self._layouts:
            self._layouts[name] = build()
        return self._layouts[name]

    @property
    def signal(self):
        return self._get("signal", lambda: wp.array(vec2_of(self.sig), dtype=wp.vec2f, device=self.device))

    @property
    def n_tx_pad(self) -> int:
        """Tx rows appended (zero signal) to make the Tx count a multiple of TX_CHUNK."""
        return -len(self.tx_m) % int(TX_CHUNK)

    @property
    def signal_padded(self):
        return self._get("signal_padded", lambda: wp.array(
            vec2_of(np.pad(self.sig, ((0, 0), (0, 0), (0, self.n_tx_pad)))), dtype=wp.vec2f, device=self.device))

    @property
    def tx_padded(self):
        return _constant(self._antenna_key + ("tx_padded",), lambda: wp.array(
            np.pad(self.tx_m, ((0, self.n_tx_pad), (0, 0)), mode="edge").astype(np.float32), dtype=wp.vec3f,
            device=self.device))

    def range_tables(self, rplan):
        """(twiddles, profile shift, frequency grid indices) of the range-compressed gather, uploaded once per
        frequency plan (the profiles read the raw frame, `raw_device`, directly)."""
        def build():
            m = np.arange(rplan.n_samples)
            dev = self.device
            return (wp.array(vec2_of(np.exp(2j * np.pi * m / rplan.n_samples)), dtype=wp.vec2f, device=dev),
                    wp.array(vec2_of(range_compression.profile_shift(rplan)), dtype=wp.vec2f, device=dev),
                    wp.array(rplan.grid_index.astype(np.int32), dtype=wp.int32, device=dev))
        return _constant((self.device, "range", np.asarray(self.freqs_hz).tobytes(), rplan.n_samples,
                          rplan.f_carrier_hz), build)

    def _host_mat(self):
        """(gain (F,) float64, fp16 [[Sr, Si], [-Si, Sr]] / gain (F, 192, 192)) on the host, once per frame."""
        def build():
            n = int(TC_ANT)
            n_rx, n_tx = self.sig.shape[1:]
            sig = np.zeros((self.n_freqs, n, n), dtype=np.complex128)
            sig[:, :n_rx, :n_tx] = self.sig
            gain = np.maximum(np.abs(sig.real).max(axis=(1, 2)), np.abs(sig.imag).max(axis=(1, 2)))
            gain = np.where(gain > 0, gain, 1.0)
            sig /= gain[:, None, None]
            return gain, np.block([[sig.real, sig.imag], [-sig.imag, sig.real]]).astype(np.float16)
        return self._get("host_mat", build)

    def tile_tables(self, with_mat: bool = True, split: bool = False):
        """(rx4, tx4, gain, mat): padded antennas, per-frequency gain and fp16 [[Sr, Si], [-Si, Sr]] / gain; `mat`
        (F, 192, 192) is built (on the host) `with_mat` (Warp-CPU's kernel), else `mat` is the device-built operand
        of the CUDA kernel with its gain: M_h^T (`tx_half_tables`) or, `split`, its hi/lo parts
        (`tx_split_tables`)."""
        n = int(TC_ANT)
        rx4, tx4 = _constant(self._antenna_key + ("tc",), lambda: (
            wp.array(antennas4(self.rx_m, n), dtype=wp.vec4f, device=self.device),
            wp.array(antennas4(self.tx_m, n), dtype=wp.vec4f, device=self.device)))
        if not with_mat:
            return (rx4, tx4) + tuple(self.tx_split_tables() if split else self._device_tables())
        gain = self._get("tc_gain", lambda: wp.array(self._host_mat()[0].astype(np.float32), dtype=wp.float32,
                                                     device=self.device))
        mat = self._get("tc_mat", lambda: wp.array(np.ascontiguousarray(self._host_mat()[1]), dtype=wp.float16,
                                                   device=self.device))
        return rx4, tx4, gain, mat

    def host_tx_half_tables(self) -> np.ndarray:
        """(F, 2, 96, TC2_KP) fp16 on the host: per Tx half h the rows [M[:, h*48 + j] ; M[:, 96 + h*48 + j]] of
        M^T, with TC2_PAD zero columns appended (the specification of `table_kernels.tx_half_table`)."""
        mat = self._host_mat()[1]                                             # (F, 192, 192)
        n, hh = int(TC_ANT), int(TC2_HALF)
        halves = [np.concatenate([mat[:, :, h * hh:(h + 1) * hh], mat[:, :, n + h * hh:n + (h + 1) * hh]],
                                 axis=2).transpose(0, 2, 1) for h in range(2)]
        m = np.stack(halves, axis=1)
        return np.ascontiguousarray(np.concatenate([m, np.zeros(m.shape[:3] + (int(TC2_PAD),), dtype=np.float16)],
                                                   axis=3))

    def _device_tables(self, split: bool = False):
        """(gain (F,) float32, operand) built on the device from the raw frame (`table_kernels.launch_tables`, no host
        work but the upload of the raw samples): M_h^T (F, 2, 96, TC2_KP) fp16, or with `split` its hi/lo parts
        (F, 4, 96, TC2_KP)."""
        def build():
            dev = self.device
            gain_raw = wp.empty(self.n_freqs, dtype=wp.float32, device=dev)
            gain = wp.empty(self.n_freqs, dtype=wp.float32, device=dev)
            mat = wp.empty((self.n_freqs, 4 if split else 2, int(TC_ANT), int(TC2_KP)), dtype=wp.float16, device=dev)
            table_kernels.launch_tables(self.raw_device, wp.float32(self.scale), gain_raw, gain, mat, dev)
            return gain, mat
        return self._get("split_tables" if split else "device_tables", build)

    def tx_half_tables(self):
        """The operand M_h^T of `correlate_tiles_tx_halves` (see `host_tx_half_tables`), built on the device."""
        return self._device_tables()[1]

    def tx_split_tables(self):
        """(gain (F,) float32, (F, 4, 96, TC2_KP) fp16): the split operand of `correlate_tiles_tx_split` (kernel
        "tc3"), built on the device from the raw frame (`table_kernels.tx_split_table`)."""
        return self._device_tables(split=True)


class FrameCache:
    """Device inputs of the last FRAME_CACHE_SIZE frames, found by content (exact comparison with the cached
    frames, newest first; no hash: a CRC of the 141 KB two-frequency frame cost 0.12 ms per call), so repeated
    calls on one frame (MM-2FSK: one call per frame and prior; benchmarks) upload nothing.

    On CUDA a new frame's copy (the content later lookups compare with) is made into a pinned host buffer (recycled
    from evicted frames) and uploaded from there asynchronously; a frame of at least CHECK_BYTES is checked for
    NaN/Inf on the device after that upload (`NonFiniteSignal`), so the caller need not sum it on the host
    (`checks`)."""

    CHECK_BYTES = 1 << 20     # BP_max's 9 MB frame: the host's sum cost ~1 ms; a 2-frequency frame's ~0.02 ms

    def __init__(self, wp_device: str):
        self.wp_device = wp_device
        self.staged = not wp.get_device(wp_device).is_cpu
        self._frames: dict = {}
        self._free: dict = {}           # (shape, dtype) -> pinned buffers of evicted frames
        self._held_signal = None        # `held`: the caller's frame array during one reconstruction
        self._held: tuple | None = None   # (its small arrays, its inputs) once looked up inside `held`
        self._last = None               # weak reference to the array of the last lookup if checked (`checked`)

    def checks(self, signal: np.ndarray) -> bool:
        """Whether a lookup of `signal` checks its samples for NaN/Inf on the device (CUDA, complex64,
        >= CHECK_BYTES): a frame that has any raises `NonFiniteSignal`."""
        return self.staged and signal.dtype == np.complex64 and signal.nbytes >= self.CHECK_BYTES

    def checked(self, signal: np.ndarray) -> bool:
        """Whether the last lookup was of this very array and checked its samples (`checks`): they are finite."""
        return self._last is not None and self._last() is signal

    @contextmanager
    def held(self, signal: np.ndarray):
        """Within the block, lookups of this very array object skip the byte comparison with the cached frames
        (the caller does not change its frame during one reconstruction; BP_max looks it up three times, ~0.7 ms
        each on the H100's host); the small arrays (frequencies, antennas) are still compared."""
        self._held_signal, self._held = signal, None
        try:
            yield
        finally:
            self._held_signal, self._held = None, None

    def inputs(self, signal, freqs_hz, tx_m, rx_m) -> FrameInputs:
        parts = [np.ascontiguousarray(a) for a in (signal, freqs_hz, tx_m, rx_m)]
        is_held = self._held_signal is not None and parts[0] is self._held_signal
        if is_held and self._held is not None and all(
                _equal(a, b) for a, b in zip(parts[1:], self._held[0], strict=True)):
            inputs = self._held[1]
        else:
            inputs = self._lookup(parts, signal, freqs_hz, tx_m, rx_m)
            if is_held:
                self._held = ([a.copy() for a in parts[1:]], inputs)
        self._last = weakref.ref(signal) if isinstance(signal, np.ndarray) and self.checks(parts[0]) else None
        return inputs

    def _lookup(self, parts, signal, freqs_hz, tx_m, rx_m) -> FrameInputs:
        key = (tuple(a.shape for a in parts), tuple(a.dtype.str for a in parts))
        for cached_key, (cached, inputs, _) in reversed(self._frames.items()):
            if cached_key[:2] == key and all(_equal(a, b) for a, b in zip(parts, cached, strict=False)):
                return inputs
        inputs = FrameInputs(signal, freqs_hz, tx_m, rx_m, self.wp_device)
        staged = None
        if self.staged and parts[0].dtype == np.complex64:
            staged = self._pinned(parts[0].shape)
            inputs.stage(parts[0], staged)
            copy = staged.numpy().view(np.complex64)[..., 0]
            if self.checks(parts[0]) and not inputs.samples_finite():
                self._free[parts[0].shape].append(staged)
                raise NonFiniteSignal("the radar frame has NaN or Inf samples")
        else:
            copy = parts[0].copy()
        self._frames[key + (len(self._frames), id(inputs))] = ([copy] + [a.copy() for a in parts[1:]], inputs, staged)
        while len(self._frames) > FRAME_CACHE_SIZE:
            _, _, old = self._frames.pop(next(iter(self._frames)))
            if old is not None:
                self._free.setdefault(tuple(old.shape), []).append(old)
        return inputs

    def _pinned(self, shape) -> wp.array:
        """A pinned (R, T, F) vec2f host buffer: an evicted frame's (its upload finished: the device is synchronised
        first). The first frame of a shape allocates all the cache can hold at once (FRAME_CACHE_SIZE + 1: page-locked
        allocation costs ~ms, and the first call of a shape is the warm-up's)."""
        shape = tuple(shape)
        if shape not in self._free:
            self._free[shape] = [wp.empty(shape, dtype=wp.vec2f, device="cpu", pinned=True)
                                 for _ in range(FRAME_CACHE_SIZE + 1)]
        free = self._free[shape]
        if not free:
            return wp.empty(shape, dtype=wp.vec2f, device="cpu", pinned=True)
        wp.synchronize_device(self.wp_device)
        return free.pop()


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Byte equality of two C-contiguous arrays of one shape and dtype (stricter than np.array_equal: -0.0 and 0.0
    differ, which only costs a cache miss), their first 64 elements compared first (a new frame differs there at
    once: a full comparison of a 128-frequency frame with each cached one cost ~15 ms a BP_max call on the H100's
    host), as 8-byte words where the size allows (0.7 against 1.7 ms for a 9 MB complex64 frame here)."""
    head_a, head_b = a.reshape(-1)[:64], b.reshape(-1)[:64]
    if not np.array_equal(head_a, head_b):
        return False
    if a.nbytes % 8 == 0 and a.nbytes == b.nbytes:
        return bool(np.array_equal(a.reshape(-1).view(np.uint64), b.reshape(-1).view(np.uint64)))
    return bool(np.array_equal(a, b))


class BufferPool:
    """Pre-allocated device buffers reused between calls, one per name (outputs are copied back before a call
    returns); a new shape or dtype replaces the buffer of that name."""

    CONSTANTS_KEPT = 8      # grids differ per capture and ROI: the least recently used constants go beyond these

    def __init__(self, wp_device: str):
        self.wp_device = wp_device
        self._buffers: dict = {}
        self._constants: OrderedDict = OrderedDict()

    def get(self, name: str, shape, dtype) -> wp.array:
        key = (name, shape, dtype)
        if key not in self._buffers:
            for old in [k for k in self._buffers if k[0] == name]:
                del self._buffers[old]
            self._buffers[key] = wp.empty(shape, dtype=dtype, device=self.wp_device)
        return self._buffers[key]

    def constant(self, key, build):
        """The arrays `build()` made the first time `key` (hashable, e.g. a grid) was asked for, kept for the
        CONSTANTS_KEPT most recently used keys. A caller that keeps using them beyond its call (a captured CUDA
        graph replays on their memory) holds its own reference: the pool drops an evicted key's."""
        if key in self._constants:
            self._constants.move_to_end(key)
        else:
            self._constants[key] = build()
            while len(self._constants) > self.CONSTANTS_KEPT:
                self._constants.popitem(last=False)
        return self._constants[key]

    def pinned(self, shape, dtype, name: str = "pinned") -> wp.array:
        """A reused page-locked host staging buffer of that name (the last shape asked for)."""
        key = (name, shape, dtype)
        if key not in self._buffers:
            for old in [k for k in self._buffers if k[0] == name]:
                del self._buffers[old]
            self._buffers[key] = wp.empty(shape, dtype=dtype, device="cpu", pinned=True)
        return self._buffers[key]

    def pinned_flat(self, n: int, dtype, name: str) -> wp.array:
        """A reused page-locked 1-d host buffer of that name holding at least n elements (it only grows: sizes that
        change from call to call, a capture's ROI, do not reallocate page-locked memory, ~ms, each time); pageable
        on Warp-CPU."""
        have = [k for k in self._buffers if k[0] == name and k[2] == dtype]
        if have and have[0][1] >= n:
            return self._buffers[have[0]]
        for old in [k for k in self._buffers if k[0] == name]:
            del self._buffers[old]
        pinned = not wp.get_device(self.wp_device).is_cpu
        self._buffers[(name, n, dtype)] = buffer = wp.empty(n, dtype=dtype, device="cpu", pinned=pinned)
        return buffer
