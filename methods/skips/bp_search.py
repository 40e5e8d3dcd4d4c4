"""BP without the empty volume: a coarse-to-fine search of each pixel's depth peak, a filter-aware pixel skip, and
the coarse pass that bounds the object (methods.skips.roi) - all on arbitrary point sets through one `evaluate` function
(frequency-summed correlation at points: BLAS per frequency, or the CPU range-compressed gather).

Search (per pixel, on the fine depth samples z_k of the grid inside the ROI):
1. coarse samples every `step` fine samples (and the last one);
2. candidates: coarse samples within a window (dB) of the pixel's coarse maximum;
3. refine by halving: around each candidate c of a level of spacing s evaluate c +- ceil(s / 2); the next level's
   candidates are the evaluated samples within its (smaller) window of the pixel's maximum so far; down to 1;
4. climb: while a pixel's argmax has an unevaluated neighbour, evaluate it (the parabola needs both neighbours,
   and a peak that moved to a window's edge keeps climbing);
5. depth and max projection by `methods.ops.depth_peak.peak_depth_m` on the evaluated samples (unevaluated ones never
win).

When it finds the full grid's peak. Let loss(d) bound how far |V(z)| falls (in dB) at distance d from any of its
peaks. The coarse sample nearest the continuous peak z* lies within step/2 of it, so it is at most
loss(step dz / 2) below |V(z*)|, which is >= every coarse sample: it is a candidate whenever
candidate_db >= loss(step dz / 2). The fine grid's maximum sits within dz / 2 of the continuous peak of its own
lobe, so that lobe's nearest coarse sample is a candidate too once the window >= loss(step dz / 2) + loss(dz / 2).
Each halving keeps the peak within half a spacing of a candidate (c, c +- ceil(s / 2) cover c +- s / 2), so with
every level's window >= loss(half its spacing) + loss(dz / 2) the search returns the full grid's argmax (tests:
exact on random sums of Gaussians, where loss is known, and a constructed miss when the window is too small).
For radar profiles loss is the fall of the point-spread function along z: the frequencies set it (two
frequencies: the beat of period c / (2 (f2 - f1)); many: the range resolution c / (2 B)) and so does the
aperture (its depth of focus, shortest at the nearest depth; off the array axis a depth step also leaves the
laterally narrow focus, which is tilted along the line of sight, so the fall is faster there). `plan_search`
measures it on point targets at 0-22 cm from the axis at the ROI's nearest depth and gives each pixel the largest
step with loss(step dz / 2) <= psf_max_loss_db at its distance from the axis, and candidate_db = that loss +
candidate_margin_db (>= loss(dz / 2), tiny). Extended scenes can have peaks sharper than a point target's
(interference); the margin covers that, and `bench.perf.correlate --section skips` measures it on the catalogue.

Measured shortcuts (options of `search_depth`; the condition above no longer guarantees the full grid's
argmax with them, so `bench.perf skips` and docs/measurements/formation.md measure them against it):
* local maxima only (`local_max`): a candidate must also be no smaller than the nearest evaluated samples on either
  side in its pixel. On a lobe that is unimodal between evaluated samples the halving then brackets the lobe's
  peak (the largest of c - h, c, c + h is within h of it) and a lobe's flank samples add nothing; two-frequency
  profiles are smooth over a coarse step (their envelope varies over the depth of focus and the beat), so a
  pixel's refinement costs ~2 samples per level and lobe instead of 2 per sample within the window.
* pixel lattice (`Lattice`): only the pixels on a lattice of `step` pixels (and those not enclosed by four lattice
  pixels of the set) evaluate every coarse sample; each other pixel evaluates the coarse samples within one coarse
  step of its lattice corners' candidates (within the window + `margin_db`), and the refinement goes on from its
  own values. The image is laterally smooth over the lattice (2 mm against a lateral resolution of ~4 mm at 30
  cm), so a pixel's peak lies where its corners' peaks are. With `weak_db` >= 0 a pixel whose four corners' coarse
  maxima all lie weak_db below the filter-aware skip level (below) evaluates nothing (depth NaN, magnitude 0).
  The magnitude is smooth over the lattice but the depth of broad (two-frequency) lobes need not be: a pixel can
  hold its peak where no corner has a candidate (the catalogue's bottle, formation.md 14). With `recheck_db` >= 0 a
  pixel whose peak after its search lies more than recheck_db below the mean (dB) of its corners' peaks, where that
  mean reaches the filter-aware skip level, takes every coarse sample and is searched again, as a lattice pixel.
* vertex jump (`jump`): a pixel with a single candidate after the coarse samples refines at the vertex of the
  parabola (in dB) through the candidate and its nearest evaluated samples, +- 1 sample, and the climb ends it,
  instead of halving (~3 samples instead of ~6 for a lobe that is smooth over a coarse step, as with few
  frequencies; pixels with several candidates keep the halving, where the lobes compete).
Values the coarse ROI's pass evaluated (`known`) are taken instead of evaluated again: the same search.

Filter-aware skip: a pixel is kept by the filter iff max_z |V| >= G 10^(-thr/20) with G the image maximum.
Under the condition above, max_z |V| <= coarse_max 10^(window/20), and G >= G_coarse, so a pixel whose
coarse maximum is below G_coarse 10^(-(thr + window)/20) cannot be kept: it is not refined, its depth is NaN
and its magnitude the coarse maximum (a lower bound; it stays below the filter).
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from methods.domain.antennas import AntennaArray
from methods.ops.correlate import C_M_PER_S
from methods.ops.depth_peak import peak_depth_m
from methods.skips.roi import Roi, dilate, lattice

Evaluate = Callable[[np.ndarray], np.ndarray]      # points (N, 3) m -> frequency-summed correlation (N,) complex
# (x_m, y_m, z_m, step) -> (coarse maximum (N,), its first depth index (N,), samples evaluated), or None: the host
CoarsePeaks = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], "tuple[np.ndarray, np.ndarray, int] | None"]
BATCH_POINTS = 1 << 16                             # points per evaluate call (128 frequencies: 64 MB of phasors)
SMALL_SUBSET = 8                                   # fewer than 1/8 of the pixels: read their rows, not the whole array


@dataclass(frozen=True)
class SearchPlan:
    """Per searched pixel (N,): the coarse step in fine samples, and `loss_curve_db` (N, n_max): the point-target
    loss at k dz / 2 for k = 1..n_max (the candidate window of a level of spacing k is loss_curve_db[:, k - 1] +
    `margin_db`)."""

    step: np.ndarray
    loss_curve_db: np.ndarray
    margin_db: float = 0.0

    def candidate_db(self, spacing: np.ndarray) -> np.ndarray:
        """Candidate window (N,) dB of a level whose samples are `spacing` (N,) fine samples apart."""
        k = np.clip(spacing, 1, self.loss_curve_db.shape[1]) - 1
        return self.loss_curve_db[np.arange(len(k)), k] + self.margin_db

    @staticmethod
    def every_sample(n_px: int) -> SearchPlan:
        """Step 1 everywhere: every fine sample is evaluated (the full search over the given depths)."""
        return SearchPlan(np.ones(n_px, dtype=int), np.zeros((n_px, 1)))

    @staticmethod
    def uniform(n_px: int, step: int, loss_curve_db: np.ndarray, margin_db: float = 0.0) -> SearchPlan:
        """The same step and loss curve (n_max,) for every pixel."""
        curve = np.asarray(loss_curve_db, dtype=float)
        return SearchPlan(np.full(n_px, step), np.broadcast_to(curve, (n_px, len(curve))), margin_db)


@dataclass(frozen=True)
class Evaluated:
    """|V| a coarse pass evaluated, for the search to reuse: at the grid pixels (rows, cols) (L,) and the depths
    z_m (n_z,), `mag` (L, n_z) float32, -1 where not evaluated."""

    rows: np.ndarray
    cols: np.ndarray
    z_m: np.ndarray
    mag: np.ndarray

    def for_search(self, rows: np.ndarray, cols: np.ndarray, z_m: np.ndarray) -> Known | None:
        """These values where the search of the grid pixels (rows, cols) (N,) over the depths z_m (equidistant, a
        contiguous run of this pass's depths) would evaluate them; None where the depths do not line up."""
        if len(z_m) == 0 or len(self.z_m) == 0:
            return None
        shift = int(np.argmin(np.abs(self.z_m - z_m[0])))
        overlap = min(len(z_m), len(self.z_m) - shift)
        if not np.array_equal(self.z_m[shift:shift + overlap], z_m[:overlap]):
            return None
        index = np.full((int(max(rows.max(initial=0), self.rows.max(initial=0))) + 1,
                         int(max(cols.max(initial=0), self.cols.max(initial=0))) + 1), -1, dtype=np.int64)
        index[self.rows, self.cols] = np.arange(len(self.rows))
        return Known(index[rows, cols], self.mag[:, shift:shift + overlap])


@dataclass(frozen=True)
class Known:
    """|V| known before the search: per searched pixel (N,) its row of `mag` (-1: none) and `mag` (L, n_k)
    float32 at the search's first n_k depth indices (-1: not known)."""

    slot: np.ndarray
    mag: np.ndarray

    def take(self, k: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The known |V| at (depth index, pixel) (n,), -1 where not known."""
        slot = self.slot[p]
        hit = (slot >= 0) & (k < self.mag.shape[1])
        out = np.full(len(k), -1.0, dtype=np.float32)
        out[hit] = self.mag[slot[hit], k[hit]]
        return out


@dataclass
class SearchResult:
    """Per searched pixel: depth (NaN = filtered out by the skip, or peak on an ROI depth edge that is not a grid
    edge), max projection, and the number of (pixel, depth) samples evaluated."""

    depth_m: np.ndarray
    max_projection: np.ndarray
    n_evaluated: int


def point_target_loss_db(freqs_hz: np.ndarray, antennas: AntennaArray, points_m: np.ndarray, offsets_m: np.ndarray
                         ) -> np.ndarray:
    """Worst (over the point targets `points_m` (K, 3) and both sides) drop in dB of |V(z)| at `offsets_m` (>= 0,
    ascending) from the peak of each target's own depth profile (sampled every 0.25 mm around its depth).

    For a point target the pair sum factorises: V(z) = sum_f A_f(z) B_f(z) with A_f = sum_r exp(j k_f (|p - rx_r|
    - |p0 - rx_r|)) and B_f the same over tx, so a profile costs (n_rx + n_tx) F phasors per depth (float64)."""
    fine_m = np.arange(-offsets_m[-1] - 0.004, offsets_m[-1] + 0.004 + 1e-12, 0.00025)
    k = 2.0 * np.pi * np.asarray(freqs_hz, dtype=np.float64) / C_M_PER_S            # (F,)
    worst = np.zeros(len(offsets_m))
    for p in np.atleast_2d(points_m):
        column = np.column_stack([np.full(len(fine_m), p[0]), np.full(len(fine_m), p[1]), p[2] + fine_m])

        def side_sum(ant_m, column=column, p=p):
            delta = (np.linalg.norm(column[:, None] - ant_m[None], axis=2)
                     - np.linalg.norm(p[None] - ant_m, axis=1)[None])              # (Z, A) path change
            return _phasor_sums(delta, k)
        mag = np.abs((side_sum(antennas.rx_m) * side_sum(antennas.tx_m)).sum(axis=1))
        peak_z = fine_m[np.argmax(mag)]
        for side in (-1.0, 1.0):
            at = np.interp(peak_z + side * offsets_m, fine_m, mag)
            worst = np.maximum(worst, 20.0 * np.log10(mag.max() / np.maximum(at, 1e-30)))
    return worst


def _phasor_sums(delta_m: np.ndarray, k: np.ndarray) -> np.ndarray:
    """sum_a exp(j k_f delta_a) (Z, F) for path changes delta_m (Z, A) and wavenumbers k (F,). Equidistant k
    (BP_max's 128) factor as k_(i + n j) = (k_0 + i dk) + n j dk: per depth one (n_hi, A) x (A, n) complex product of
    n + n_hi phasor tables instead of F phasors per antenna (5x less work; equal to the direct sum within ~1e-15
    relative, float64)."""
    n_f = len(k)
    n = int(np.ceil(np.sqrt(n_f)))
    dk = (k[-1] - k[0]) / max(n_f - 1, 1)
    if n_f < 16 or not np.allclose(np.diff(k), dk, rtol=1e-9, atol=0.0):
        return np.exp(1j * delta_m[:, :, None] * k[None, None]).sum(axis=1)
    n_hi = -(-n_f // n)
    lo = np.exp(1j * delta_m[:, :, None] * (k[0] + dk * np.arange(n))[None, None])          # (Z, A, n)
    hi = np.exp(1j * delta_m[:, None, :] * (dk * n * np.arange(n_hi))[None, :, None])       # (Z, n_hi, A)
    return np.matmul(hi, lo).reshape(len(delta_m), n_hi * n)[:, :n_f]


PROBE_RADII_M = tuple(np.round(np.arange(0.0, 0.2201, 0.02), 3))   # probe distances from the array axis, m


@functools.lru_cache(maxsize=32)
def _loss_by_radius(freqs_key: tuple[float, ...], antennas_key: bytes, z_near_m: float, dz_m: float, n_max: int
                    ) -> np.ndarray:
    """(len(PROBE_RADII_M), n_max) loss in dB at offsets k dz / 2 (k = 1..n_max), worst over 4 directions per
    radius. Depends only on the frequencies, the array and the depth: computed once per process and configuration."""
    antennas = _ANTENNAS[antennas_key]
    freqs_hz = np.asarray(freqs_key)
    offsets_m = np.arange(1, n_max + 1) * dz_m / 2.0
    out = np.empty((len(PROBE_RADII_M), n_max))
    for i, r in enumerate(PROBE_RADII_M):
        d = r / np.sqrt(2.0)
        probes = np.array([[r, 0.0], [0.0, r], [d, d], [d, -d]]) if r > 0 else np.zeros((1, 2))
        points_m = np.column_stack([probes, np.full(len(probes), z_near_m)])
        out[i] = point_target_loss_db(freqs_hz, antennas, points_m, offsets_m)
    return out


_ANTENNAS: dict[bytes, AntennaArray] = {}


def plan_search(freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray, y_m: np.ndarray, z_near_m: float,
                dz_m: float, max_loss_db: float, max_step_m: float, margin_db: float) -> SearchPlan:
    """Per pixel (x_m, y_m) (N,): the largest coarse step (a multiple of dz_m, <= max_step_m) whose point-target
    loss at half a step is <= max_loss_db, measured at the probe radius at or beyond the pixel's lateral distance
    from the array axis and at the ROI's nearest depth z_near_m (where the depth of focus is shortest);
    candidates within that loss + margin_db. (The loss grows off axis: there a depth step also leaves the
    laterally narrow focus, which is tilted along the line of sight.)"""
    n_max = max(1, int(np.floor(max_step_m / dz_m + 1e-9)))
    key = np.ascontiguousarray(np.concatenate([antennas.rx_m.ravel(), antennas.tx_m.ravel()])).tobytes()
    _ANTENNAS.setdefault(key, antennas)
    loss = _loss_by_radius(tuple(np.asarray(freqs_hz, dtype=np.float64).tolist()), key, round(float(z_near_m), 6),
                           float(dz_m), n_max)                                  # (radii, n_max)
    # a pixel between two probe radii takes the larger loss of the two (the loss grows off axis, not strictly)
    bracket = np.maximum(loss, np.vstack([loss[:1], loss[:-1]]))               # (radii, n_max)
    ok = bracket <= max_loss_db
    best = np.where(ok.any(axis=1), n_max - np.argmax(ok[:, ::-1], axis=1), 1)  # largest k with loss <= max
    step_by_radius = np.minimum.accumulate(best[::-1])[::-1]                  # monotone: never larger farther out
    radius = np.hypot(x_m, y_m)
    ring = np.minimum(np.searchsorted(np.asarray(PROBE_RADII_M), radius - 1e-12), len(PROBE_RADII_M) - 1)
    return SearchPlan(step=step_by_radius[ring].astype(int), loss_curve_db=bracket[ring], margin_db=margin_db)


@dataclass(frozen=True)
class Lattice:
    """The searched pixels' grid rows and columns (N,) and a lattice of `step_px` pixels (module doc): the others
    inherit their coarse samples from the candidates of their lattice corners within the window + `margin_db`;
    `weak_db`, `recheck_db` (dB, < 0: off): the module doc's weak corners and re-check."""

    rows: np.ndarray
    cols: np.ndarray
    step_px: int
    margin_db: float
    weak_db: float = -1.0
    recheck_db: float = -1.0

    def corners(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 4) indices of each pixel's enclosing lattice pixels (-1: not in the set) and (N,) bool: the pixel
        evaluates its own coarse samples (on the lattice, or a corner missing)."""
        step, n = self.step_px, len(self.rows)
        r0, c0 = self.rows // step * step, self.cols // step * step
        r1 = np.where(self.rows % step > 0, r0 + step, r0)
        c1 = np.where(self.cols % step > 0, c0 + step, c0)
        index = np.full((int(r1.max(initial=0)) + 1, int(c1.max(initial=0)) + 1), -1, dtype=np.int64)
        index[self.rows, self.cols] = np.arange(n)
        corners = np.stack([index[r0, c0], index[r0, c1], index[r1, c0], index[r1, c1]], axis=1)
        on_lattice = (self.rows % step == 0) & (self.cols % step == 0)
        return corners, on_lattice | (corners < 0).any(axis=1)


def _candidates(mag: np.ndarray, rows: np.ndarray, ratio: np.ndarray, local_max: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(pixel, depth index), pixel-major, of the evaluated samples of |V| `mag` (n_px, n_z) (-1: not evaluated) in
    the pixels `rows` (ascending) within `ratio` (len(rows),) of their pixel's maximum and, with `local_max`, no
    smaller than their pixel's nearest evaluated samples on either side (module doc); and the depth indices of
    those nearest evaluated samples (left, right; -1: none). Works on the list of evaluated samples (~25 of a
    pixel's ~200 depths), found in one pass over `mag` (no copy of the rows), or over a copy of the rows where
    they are few (the re-checked pixels)."""
    n_z = mag.shape[1]
    if SMALL_SUBSET * len(rows) < len(mag):
        block = mag[rows]
        flat = np.flatnonzero(block >= 0)                                      # pixel-major, depth ascending
        pixel, vals = rows[flat // n_z], block.ravel()[flat]
    else:
        flat = np.flatnonzero(mag >= 0)
        asked = np.zeros(len(mag), dtype=bool)
        asked[rows] = True
        flat = flat[asked[flat // n_z]]
        pixel, vals = flat // n_z, mag.ravel()[flat]
    starts = np.flatnonzero(np.concatenate(([True], pixel[1:] != pixel[:-1]))) if len(flat) else flat
    ratio_of = np.zeros(len(mag))
    ratio_of[rows] = ratio
    level = np.maximum.reduceat(vals, starts) * ratio_of[pixel[starts]] if len(flat) else vals
    keep = vals >= np.repeat(level, np.diff(np.append(starts, len(flat))))
    first = np.zeros(len(flat) + 1, dtype=bool)                                # first[i]: sample i starts a pixel
    first[starts] = True
    first[-1] = True
    if local_max:
        keep[1:] &= first[1:-1] | (vals[1:] >= vals[:-1])
        keep[:-1] &= first[1:-1] | (vals[:-1] >= vals[1:])
    idx = np.flatnonzero(keep)
    k = flat % n_z
    left = np.where(first[idx], -1, k[np.maximum(idx - 1, 0)])
    right = np.where(first[idx + 1], -1, k[np.minimum(idx + 1, len(flat) - 1)])
    return pixel[idx], k[idx], left, right


def _vertex(mag: np.ndarray, pixel: np.ndarray, k: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Depth index (rounded) of the vertex of the parabola in dB through each sample (pixel, k) of `mag` and its
    nearest evaluated samples `left` and `right` (-1: none), strictly between those; k itself where a side has none
    or the three are not concave."""
    ok = (left >= 0) & (right >= 0)
    x1, x2, x3 = (np.where(ok, a, k).astype(np.float64) for a in (left, k, right))
    y1, y2, y3 = (20.0 * np.log10(np.maximum(mag[pixel, np.where(ok, a, k)], 1e-30).astype(np.float64))
                  for a in (left, k, right))
    den = (x2 - x1) * (y2 - y3) - (x2 - x3) * (y2 - y1)
    ok &= (den != 0) & (y2 >= y1) & (y2 >= y3)
    num = (x2 - x1) ** 2 * (y2 - y3) - (x2 - x3) ** 2 * (y2 - y1)
    vertex = np.rint(np.where(ok, x2 - 0.5 * num / np.where(ok, den, 1.0), x2)).astype(np.int64)
    return np.where(ok, np.clip(vertex, left + 1, np.maximum(left + 1, right - 1)), k)


def _near_coarse(marked: np.ndarray, k_c: np.ndarray) -> np.ndarray:
    """(n, len(k_c)) bool: a depth of `marked` (n, n_z) lies between the coarse sample's neighbours k_c[i - 1] and
    k_c[i + 1] (inclusive; within one coarse step)."""
    segment = np.logical_or.reduceat(marked, k_c, axis=1)                      # [k_c[i], k_c[i + 1]), last: k_c[-1]
    near = segment.copy()
    near[:, 1:] |= segment[:, :-1]
    near[:, :-1] |= marked[:, k_c[1:]]
    return near


def _unique(values: np.ndarray) -> np.ndarray:
    """The distinct values of an integer array, ascending: `np.unique` by a sort (NumPy 2.4's `np.unique` hashes,
    ~20x slower here: 31 ms against 1.4 ms for 150 k keys)."""
    ordered = np.sort(values)
    return ordered[np.concatenate(([True], ordered[1:] != ordered[:-1]))] if len(ordered) else ordered


def _coarse_indices(n_z: int, step: int) -> np.ndarray:
    k = np.arange(0, n_z, step)
    return k if k[-1] == n_z - 1 else np.append(k, n_z - 1)


class _Samples:
    """|V| `mag` (pixel, fine depth index), -1 where not evaluated (pixel-major: the search reads and writes a
    pixel's depths together); evaluates batches of (k, pixel) through `evaluate`."""

    def __init__(self, evaluate: Evaluate, x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray,
                 window: tuple[np.ndarray, np.ndarray] | None = None, known: Known | None = None):
        self.evaluate, self.x_m, self.y_m, self.z_m, self.window, self.known = evaluate, x_m, y_m, z_m, window, known
        self.mag = np.full((len(x_m), len(z_m)), -1.0, dtype=np.float32)
        self.count = 0

    def run(self, k: np.ndarray, p: np.ndarray) -> None:
        """|V| at (depth index, pixel) (n,): taken from `known` where it holds them, else evaluated (and counted)."""
        if self.known is not None and len(k):
            value = self.known.take(k, p)
            hit = value >= 0
            if hit.any():
                self.mag[p[hit], k[hit]] = value[hit]
                k, p = k[~hit], p[~hit]
        for start in range(0, len(k), BATCH_POINTS):      # bounded memory: correlate holds (F, batch) phasors
            kb, pb = k[start:start + BATCH_POINTS], p[start:start + BATCH_POINTS]
            points_m = np.column_stack([self.x_m[pb], self.y_m[pb], self.z_m[kb]])
            self.mag[pb, kb] = np.abs(self.evaluate(points_m))
        self.count += len(k)

    def run_coarse(self, step: np.ndarray, pixels: np.ndarray | None = None) -> np.ndarray:
        """Evaluate the coarse samples (each pixel's `step` (N,)) of `pixels` (indices; default all) inside each
        pixel's depth window where one is set (`window`: lowest and highest depth index (N,)); returns the coarse
        maximum per pixel (N,) (0 for the others)."""
        n_z = len(self.z_m)
        pixels = np.arange(len(step)) if pixels is None else pixels
        coarse_max = np.zeros(len(step), dtype=np.float32)
        for s in _unique(step[pixels]):
            pix = pixels[step[pixels] == s]
            k_c = _coarse_indices(n_z, int(s))
            pp, kk = np.meshgrid(pix, k_c, indexing="ij")     # pixel-major: a batch's points lie close together
            todo = self.mag[pp, kk] < 0                       # not evaluated yet (a re-checked pixel has some)
            if self.window is not None:
                todo &= (kk >= self.window[0][pp]) & (kk <= self.window[1][pp])
            self.run(kk[todo], pp[todo])
            coarse_max[pix] = np.maximum(self.mag[np.ix_(pix, k_c)].max(axis=1), 0.0)
        return coarse_max

    def run_inherited(self, step: np.ndarray, window: np.ndarray, lattice: Lattice, local_max: bool,
                      keep_ratio: float | None = None) -> None:
        """The coarse pass with a pixel lattice (module doc): every coarse sample of the lattice's pixels, then at
        each other pixel its coarse samples within one coarse step of its corners' candidates (between the coarse
        neighbours of the sample). With `keep_ratio` (the filter's 10^(-threshold / 20)) and the lattice's
        `weak_db` >= 0, a pixel whose corners' coarse maxima all lie more than weak_db below the skip level
        (keep_ratio x its window x the lattice's coarse maximum) evaluates nothing."""
        n_z = len(self.z_m)
        corners, own = lattice.corners()
        own_px = np.flatnonzero(own)
        self.run_coarse(step, own_px)
        inherit = np.flatnonzero(~own)
        if keep_ratio is not None and lattice.weak_db >= 0 and len(inherit):
            own_max = np.maximum(self.mag[own_px].max(axis=1), 0.0)
            corner_max = np.zeros(len(step), dtype=np.float32)
            corner_max[own_px] = own_max
            level = own_max.max(initial=0.0) * keep_ratio * 10.0 ** (-lattice.weak_db / 20.0)
            inherit = inherit[corner_max[corners[inherit]].max(axis=1) >= level * window[inherit]]
        if len(inherit) == 0:
            return
        own_row = np.full(len(step), -1)                                       # corners are lattice pixels: own
        own_row[own_px] = np.arange(len(own_px))
        marked = np.zeros((len(own_px), n_z), dtype=bool)                     # (own pixel, depth): candidates
        p, k, _, _ = _candidates(self.mag, own_px, window[own_px] * 10.0 ** (-lattice.margin_db / 20.0),
                                 local_max)
        marked[own_row[p], k] = True
        for s in _unique(step[inherit]):
            sel = inherit[step[inherit] == s]
            k_c = _coarse_indices(n_z, int(s))
            near = _near_coarse(marked, k_c)               # per corner: "near" is an OR, so it commutes with the union
            union = near[own_row[corners[sel, 0]]]
            for j in range(1, corners.shape[1]):
                union |= near[own_row[corners[sel, j]]]
            p, c = np.nonzero(union)                                            # pixel-major
            self.run(k_c[c], sel[p])


def search_depth(evaluate: Evaluate, x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray, plan: SearchPlan,
                 threshold_db: float | None, z_edges_are_grid_edges: tuple[bool, bool] = (True, True),
                 lattice: Lattice | None = None, local_max: bool = False,
                 z_window: tuple[np.ndarray, np.ndarray] | None = None, known: Known | None = None,
                 jump: bool = False) -> SearchResult:
    """Coarse-to-fine depth peak (module doc) of the pixels (x_m, y_m) (N,) over the equidistant depths z_m (n_z,);
    `lattice` and `local_max`: the module doc's shortcuts (off: the search whose condition is proved there);
    `z_window`: each pixel's lowest and highest depth index (N,) for its own coarse samples (the coarse ROI's local
    depth bounds, `Roi.z_window_m`); refinement and climb are not bounded by it. `known`: values the coarse ROI's
    pass evaluated (`Evaluated.for_search`), taken instead of evaluating them again where the search needs them (the
    same samples and values, fewer evaluations).

    Refinement halves the spacing level by level (ceil(s / 2)): around each candidate c of a level of spacing s,
    c +- ceil(s / 2) are evaluated, and the candidates of the new level are the evaluated samples within its
    window (loss at half the new spacing + margin) of the pixel's maximum so far; at spacing 1 the climb ends it.
    A peak on a depth edge of z_m that is not an edge of the grid (`z_edges_are_grid_edges` False there: the ROI
    cut the grid) gives NaN: the pixel's peak may lie outside the ROI. With step 1 every sample is evaluated.
    """

    n_z, n_px = len(z_m), len(x_m)
    dz_m = float(z_m[1] - z_m[0]) if n_z > 1 else 1.0
    step = np.minimum(plan.step, max(n_z - 1, 1))
    samples = _Samples(evaluate, x_m, y_m, z_m, z_window, known)
    window = 10.0 ** (-plan.candidate_db(step) / 20.0)                        # (N,)
    keep_ratio = None if threshold_db is None else 10.0 ** (-threshold_db / 20.0)
    on_lattice = lattice is not None and lattice.step_px > 1
    if on_lattice:
        samples.run_inherited(step, window, lattice, local_max, keep_ratio)
        coarse_max = np.maximum(samples.mag.max(axis=1), 0.0)                  # unevaluated: -1
    else:
        coarse_max = samples.run_coarse(step)
    active = coarse_max > 0
    if keep_ratio is not None and active.any():
        active &= coarse_max >= coarse_max.max() * keep_ratio * window
    _refine(samples, plan, np.where(active, step, 1), local_max, jump)
    _climb(samples, active)
    if on_lattice and lattice.recheck_db >= 0:
        level = 0.0 if keep_ratio is None else coarse_max.max() * keep_ratio
        again = _rechecked(samples.mag, lattice, level * window)
        if again.any():                              # searched again with every coarse sample, as a lattice pixel
            pixels = np.flatnonzero(again)
            coarse_max[pixels] = np.maximum(coarse_max[pixels], samples.run_coarse(step, pixels)[pixels])
            again &= coarse_max >= level * window
            active |= again
            _refine(samples, plan, np.where(again, step, 1), local_max, jump)
            _climb(samples, again)
    depth_m = np.full(n_px, np.nan)
    max_proj = coarse_max.astype(np.float64)
    if active.any():
        mag = samples.mag[active].T
        depth_m[active], max_proj[active] = peak_depth_m(mag, float(z_m[0]), dz_m)
        k_best = np.argmax(mag, axis=0)
        on_cut = ((k_best == 0) & (not z_edges_are_grid_edges[0])) | ((k_best == n_z - 1) &
                                                                       (not z_edges_are_grid_edges[1]))
        depth_m[np.flatnonzero(active)[on_cut]] = np.nan
    return SearchResult(depth_m, max_proj, samples.count)


def _refine(samples: _Samples, plan: SearchPlan, spacing: np.ndarray, local_max: bool, jump: bool) -> None:
    """The halving (`search_depth`'s doc) of the pixels whose coarse `spacing` (N,) is > 1 (the others: 1), from the
    samples evaluated so far; with `jump`, a pixel's single candidate of the first level jumps to its lobe's vertex."""
    n_px, n_z = samples.mag.shape
    window = 10.0 ** (-plan.candidate_db(spacing) / 20.0)
    first = True
    while (spacing > 1).any():
        refining = np.flatnonzero(spacing > 1)
        p, k, left, right = _candidates(samples.mag, refining, window[refining], local_max)
        k_jump, p_jump = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        if jump and first:                    # a pixel's only candidate: its lobe's vertex and the two beside it
            alone = np.bincount(p, minlength=n_px)[p] == 1
            p_jump, k_mid = p[alone], _vertex(samples.mag, p[alone], k[alone], left[alone], right[alone])
            k_jump, p_jump = np.concatenate([k_mid - 1, k_mid, k_mid + 1]), np.tile(p_jump, 3)
            spacing[p[alone]] = 1
            p, k = p[~alone], k[~alone]
        first = False
        spacing = np.where(spacing > 1, (spacing + 1) // 2, spacing)
        half = spacing[p]
        k_new = np.concatenate([k - half, k + half, k_jump])
        p_new = np.concatenate([p, p, p_jump])
        inside = (k_new >= 0) & (k_new < n_z)
        k_new, p_new = k_new[inside], p_new[inside]
        fresh = samples.mag[p_new, k_new] < 0
        key = _unique(p_new[fresh].astype(np.int64) * n_z + k_new[fresh])       # pixel-major, no duplicates
        samples.run(key % n_z, key // n_z)
        window = 10.0 ** (-plan.candidate_db(spacing) / 20.0)


def _rechecked(mag: np.ndarray, lattice: Lattice, level: np.ndarray) -> np.ndarray:
    """(N,) bool: the pixels that took their coarse samples from their lattice corners and whose peak so far lies
    more than `lattice.recheck_db` below the mean (in dB) of their corners' peaks, where that mean reaches `level`
    (N,) (the filter-aware skip level: below it the pixel cannot matter to the filter)."""
    corners, own = lattice.corners()
    peak_db = 20.0 * np.log10(np.maximum(mag.max(axis=1), 1e-30).astype(np.float64))
    inherit = np.flatnonzero(~own)
    corner_db = peak_db[corners[inherit]].mean(axis=1)
    out = np.zeros(len(mag), dtype=bool)
    out[inherit] = ((peak_db[inherit] < corner_db - lattice.recheck_db)
                    & (corner_db >= 20.0 * np.log10(np.maximum(level[inherit], 1e-30))))
    return out


def _climb(samples: _Samples, active: np.ndarray) -> None:
    """Evaluate unevaluated neighbours of each active pixel's argmax until none is left."""
    n_z = samples.mag.shape[1]
    pixels = np.flatnonzero(active)
    # the first round's: no copy of most of the rows (a few rows, the re-checked pixels: their copy)
    k_all = None if SMALL_SUBSET * len(pixels) < len(samples.mag) else np.argmax(samples.mag, axis=1)
    for _ in range(n_z):
        if len(pixels) == 0:
            return
        k_best = k_all[pixels] if k_all is not None else np.argmax(samples.mag[pixels], axis=1)
        k_all = None
        new_k, new_p = [], []
        for side in (-1, 1):
            k = k_best + side
            inside = (k >= 0) & (k < n_z)
            missing = np.zeros(len(pixels), dtype=bool)
            missing[inside] = samples.mag[pixels[inside], k[inside]] < 0
            new_k.append(k[missing])
            new_p.append(pixels[missing])
        k, p = np.concatenate(new_k), np.concatenate(new_p)
        if len(k) == 0:
            return
        order = np.argsort(p, kind="stable")
        samples.run(k[order], p[order])
        pixels = _unique(p)


def _coarse_two_pass(samples: _Samples, step: np.ndarray, pixels: np.ndarray, grid_lattice: np.ndarray,
                     lattice_step_px: int, below_db: float) -> np.ndarray:
    """The coarse ROI's samples on the lattice `grid_lattice` (ny, nx) bool (its pixels in `samples`' order) in two
    passes: every coarse sample at the lattice pixels of every second lattice row and column first; then at the
    other lattice pixels next to (within one lattice step in x and y of) a first-pass pixel whose coarse maximum
    is within `below_db` of the first pass's maximum, or next to none. Returns the coarse maximum per lattice pixel
    (0: not evaluated). Measured, not proved: an object whose lattice pixels all lie more than `below_db` below
    the maximum at the first pass's pixels around them is not found (docs/measurements/formation.md)."""
    rows, cols = np.nonzero(grid_lattice)                  # the lattice pixels' order in `samples`
    start = lattice_step_px // 2
    first = ((rows - start) % (2 * lattice_step_px) == 0) & ((cols - start) % (2 * lattice_step_px) == 0)
    peak = samples.run_coarse(step, np.flatnonzero(first))
    strong = first & (peak >= peak.max() * 10.0 ** (-below_db / 20.0)) & (peak > 0)
    marked, seen = np.zeros_like(pixels), np.zeros_like(pixels)
    marked[rows[strong], cols[strong]] = True
    seen[rows[first], cols[first]] = True
    # next to a strong first-pass pixel (within one lattice step in x and y), or to none at all (the set's edges)
    near = (dilate(marked, lattice_step_px) | ~dilate(seen, lattice_step_px))[rows, cols] & ~first
    if near.any():
        peak = np.maximum(peak, samples.run_coarse(step, np.flatnonzero(near)))
    return peak


def coarse_roi(evaluate: Evaluate, pixels: np.ndarray, x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray,
               plan_of: Callable[[np.ndarray, np.ndarray], SearchPlan], threshold_db: float, lattice_step_px: int,
               radius_px: int, keep_margin_db: float, margin_m: float, coarse_peaks: CoarsePeaks | None = None,
               prepass_margin_db: float | None = None) -> tuple[Roi, int]:
    """The object's ROI from a coarse pass: depth samples at twice the search plan's coarse step (`plan_of(x, y)`)
    at the lattice pixels (every `lattice_step_px`-th) of `pixels` (ny, nx) bool; x_m, y_m (ny, nx) pixel centres;
    z_m the depths inside the current ROI.

    Lattice pixels whose coarse maximum is within threshold + keep_margin_db of the lattice maximum mark the pixels
    within `radius_px` in x and y; the depth range is their coarse peaks +- (that coarse step + margin_m). The
    doubled step loses at most a few dB at a peak, inside keep_margin_db. With `prepass_margin_db` (host pass
    only) the lattice is first evaluated at every second lattice pixel in x and y, and the others only next to a
    pre-pass pixel within threshold + keep_margin_db + prepass_margin_db of the pre-pass
    maximum (`_coarse_two_pass`). Returns (the ROI within `pixels` and z_m's range, samples evaluated); a host
    pass leaves its values in the ROI's `evaluated` (`Evaluated`) for the search."""
    grid_lattice = lattice(pixels, lattice_step_px)
    x_l, y_l = x_m[grid_lattice], y_m[grid_lattice]
    step = np.minimum(2 * plan_of(x_l, y_l).step, max(len(z_m) - 1, 1))
    found = coarse_peaks(x_l, y_l, z_m, step) if coarse_peaks is not None else None
    evaluated = None
    if found is None:
        samples = _Samples(evaluate, x_l, y_l, z_m)
        if prepass_margin_db is None:
            peak = samples.run_coarse(step)
        else:
            peak = _coarse_two_pass(samples, step, pixels, grid_lattice, lattice_step_px,
                                    threshold_db + keep_margin_db + prepass_margin_db)
        found = peak, np.argmax(samples.mag, axis=1), samples.count   # unevaluated hold -1: never the argmax
        evaluated = Evaluated(*np.nonzero(grid_lattice), z_m, samples.mag)
    peak, peak_k, n_evaluated = found
    peak_z = z_m[peak_k]
    strong = peak >= peak.max() * 10.0 ** (-(threshold_db + keep_margin_db) / 20.0)
    marked = np.zeros_like(pixels)
    marked[grid_lattice] = strong
    roi_pixels = dilate(marked, radius_px) & pixels
    dz_m = z_m[1] - z_m[0] if len(z_m) > 1 else 0.0
    pad_m = step[strong] * dz_m + margin_m
    # each ROI pixel's own depth bounds: those of the strong lattice pixels that marked it
    low, high = np.full(pixels.shape, np.inf), np.full(pixels.shape, -np.inf)
    rows, cols = np.nonzero(grid_lattice)
    low[rows[strong], cols[strong]] = peak_z[strong] - pad_m
    high[rows[strong], cols[strong]] = peak_z[strong] + pad_m
    size = 2 * radius_px + 1
    window = (ndimage.minimum_filter(low, size=size, mode="constant", cval=np.inf),
              ndimage.maximum_filter(high, size=size, mode="constant", cval=-np.inf))
    return (Roi(roi_pixels, float(np.min(peak_z[strong] - pad_m)), float(np.max(peak_z[strong] + pad_m)),
                ("coarse",), window, evaluated), n_evaluated)
