"""Which skips a reconstruction uses (issue 11: "skip what a scene does not need"), and their parameters.

Each skip evaluates less than the full grid and is measured against the full computation by
`python -m bench.perf correlate --section skips` (time, speed-up, depth and metric change on every catalogue object).
A skip
is on by default (`default_for`, the `roi=auto` preset) only where its depth maps agree with the full computation
within 0.1 mm on >= 99 % of the pixels valid in both and every metric within 1 % (docs/measurements/skips.md has the
numbers).

* `mask_bb`: evaluate only the pixels inside the x/y bounds of the capture's metadata `mask_bb` (methods.skips.roi).
* `mask_bb_depth`: ... and only depths inside its z bounds (BP searches no depth outside them; the other methods
  drop depths outside them). Not exact for two-frequency BP: a pixel whose strongest depth lies outside the box
  can have a weaker local peak inside it, which the full computation never reports (measured 98.2 % agreement on
  the plate); an object in front of the box holds the image maximum the filter is relative to; and a depth
  dropped at the box's edge changes the metrics' triangulation of its in-box neighbours (docs/measurements/skips.md).
* `coarse_roi`: BP without a sensor prior evaluates only the object's pixels and depth range, bounded by a coarse
  pass on a pixel lattice (methods.skips.bp_search.coarse_roi) with the margins below. Where that pass runs on the
  host it first evaluates every second lattice pixel in x and y and then only the lattice pixels next to those
  within threshold + `roi_keep_margin_db` + `roi_prepass_margin_db` of the first pass's maximum (< 0: off).
* `bp_coarse_to_fine`: BP searches each pixel's depth on a coarse step first and refines around the candidates;
  pixels whose coarse maximum proves them below the filter are not refined (methods.skips.bp_search). Where the
  search runs on the host, its measured shortcuts (bp_search's module doc): candidates only at local maxima
  (`search_local_max`) and the coarse samples of every pixel only on a `search_lattice_step_m` pixel lattice, the
  other pixels' near their lattice corners' candidates (0: off) and, where all four corners lie
  `search_lattice_weak_db` below the filter's skip level, nowhere; an other pixel whose peak then lies
  `search_lattice_recheck_db` below its corners' (mean in dB) takes every coarse sample and is searched again;
  with `search_vertex_jump` (few frequencies) a pixel with one coarse candidate refines at its lobe's parabola
  vertex; with `search_local_z` (and the coarse ROI)
  each pixel's coarse samples only within the depths of the coarse ROI's lattice pixels that marked it (their peaks +-
  the ROI's depth pad, + `search_local_z_pad_m`), not the ROI's whole depth range.
* `bp_range_cpu`: BP with many frequencies on the CPU gathers from range-compressed profiles
(methods.backends.cpu_range)
  instead of summing every frequency.
* `bp_dense_z_search`: BP on a backend that computes dense volumes (Warp) evaluates every pixel at every
  `dense_z_step_m` of depth first, then a window of +-(one coarse step + one sample) around each of its
  `dense_z_candidates` largest coarse local maxima at the full depth step (methods.backends.warp.zsearch), only at
  pixels whose coarse maximum is within the filter's threshold + `dense_z_margin_db` of the image's (the others
  cannot pass the filter); the depth is the dense volume's wherever its maximum lies in one of those windows.
* `fsk_keep`: 2FSK's second pass and 3FSK's second and fine passes run only at pixels the filter can keep,
  predicted on a pixel lattice (methods.skips.keep_skip).
`NONE` (`roi=none`) turns every skip off: the computation of today, bit for bit.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

SKIP_NAMES = ("mask_bb", "mask_bb_depth", "coarse_roi", "bp_coarse_to_fine", "bp_range_cpu", "fsk_keep",
              "bp_dense_z_search")


@dataclass(frozen=True)
class SkipSettings:
    """Switches (see the module doc) and the margins they use."""

    mask_bb: bool = False
    mask_bb_depth: bool = False
    coarse_roi: bool = False
    bp_coarse_to_fine: bool = False
    bp_range_cpu: bool = False
    fsk_keep: bool = False
    bp_dense_z_search: bool = False
    lattice_step_m: float = 0.003     # fsk_keep's lattice: a pixel every 3 mm in x and y (1/9 of 1 mm pixels)
    keep_margin_db: float = 10.0      # a lattice pixel marks its neighbourhood when within threshold + 10 dB of the max
    lattice_margin_m: float = 0.002   # the lattice neighbourhood: one lattice step + 2 mm in x and y
    roi_lattice_step_m: float = 0.004  # coarse_roi's lattice (BP): a pixel every 4 mm (1/16 of 1 mm pixels) ...
    roi_keep_margin_db: float = 6.0   # ... marking its neighbourhood when within threshold + 6 dB of the max
    roi_margin_m: float = 0.01        # the coarse ROI's depth range: lattice peaks +- (lattice depth step + 1 cm)
    roi_prepass_margin_db: float = 3.0  # >= 0: the host's coarse ROI pass on every 2nd lattice pixel first, the
    #                                   others next to those within threshold + roi_keep_margin_db + this (< 0: off)
    psf_max_loss_db: float = 3.0      # coarse depth step: largest with <= 3 dB point-target loss at half a step
    max_coarse_step_m: float = 0.01   # ... and at most 1 cm
    candidate_margin_db: float = 1.0  # refine coarse samples within (that loss + 1 dB) of the pixel's coarse max
    search_local_max: bool = True     # ... that are local maxima among the pixel's evaluated samples (host search)
    search_lattice_step_m: float = 0.002  # coarse samples at every pixel of a 2 mm lattice only (host search) ...
    search_lattice_margin_db: float = 1.0  # ... the others' near their corners' candidates within the window + 1 dB
    search_lattice_recheck_db: float = 2.0  # ... searched again with every coarse sample where their peak lies this
    #                                         far below their corners' mean in dB (< 0: off)
    search_lattice_weak_db: float = 3.0  # ... and nowhere where all four corners lie this far below the
    #                                      filter's skip level (< 0: off)
    search_vertex_jump: bool = False  # (host search) a pixel with one coarse candidate refines at the vertex of the
    #                                   parabola (dB) through it and its neighbours +- 1 sample, then climbs
    search_local_z: bool = False      # each pixel's coarse samples only within the coarse ROI's depths near it (host)
    search_local_z_pad_m: float = 0.0  # ... widened by this on each side
    dense_z_step_m: float = 0.006     # bp_dense_z_search's coarse depth step (window: +- one step at the grid's step)
    dense_z_candidates: int = 3       # ... around the pixel's 3 largest coarse local maxima, refined where its coarse
    dense_z_margin_db: float = 6.0    # maximum is within threshold + 6 dB of the image's (a point target loses <= 2.6
    #                                   dB at half a 6 mm step 15 cm off axis at 20 cm: bp_search.point_target_loss_db)

    def lattice_px(self, pixel_pitch_m: float, step_m: float | None = None) -> tuple[int, int]:
        """(lattice step, neighbourhood half-width) in pixels of `pixel_pitch_m` for a lattice of `step_m` (default
        `lattice_step_m`): a step of 1 means no lattice (the pixels are already coarser than the lattice)."""
        step = max(1, int(round((step_m or self.lattice_step_m) / pixel_pitch_m)))
        return step, step + int(np.ceil(self.lattice_margin_m / pixel_pitch_m - 1e-9))

    @property
    def any(self) -> bool:
        """Whether any skip is on."""
        return any(getattr(self, name) for name in SKIP_NAMES)

    def only(self, name: str) -> SkipSettings:
        """These parameters with exactly one skip on (bench.perf.correlate measures each skip alone)."""
        if name not in SKIP_NAMES:
            raise ValueError(f"unknown skip {name!r}; choose one of {', '.join(SKIP_NAMES)}")
        return dataclasses.replace(self, **{n: n == name for n in SKIP_NAMES})


LOCAL_Z_MIN_FREQS = 16           # BP's host search uses the coarse ROI's local depth windows from this many on
NONE = SkipSettings()
ALL = SkipSettings(**dict.fromkeys(SKIP_NAMES, True))
PRESETS = ("none", "auto", "all")


def default_for(method: str, n_freqs: int, dense_beats_search: bool = False, keeps_on_device: bool = False
                ) -> SkipSettings:
    """The skips on by default (`roi=auto`) for a method, frequency count and backend: those measured to agree with
    the full computation on every catalogue object and to save time there (docs/measurements/skips.md,
    docs/measurements/gpu.md).
    `mask_bb_depth` stays off: cutting BP's depth search at the box moved 1.8 % of two-frequency BP's depths on the
    plate and, where an object lies in front of the box (the two objects at 30 cm: one at 25 cm, zmin 26 cm), it
    removes the image maximum, so the -14 dB filter keeps other pixels (BP_max metrics moved 48 %); for 2FSK, 3FSK
    and MM-2FSK dropping depths outside the box changes which in-box pixels the metrics' triangulation keeps (up to
    5 %), for no time saved. On a backend whose `dense_beats_search` is set (Warp: "cuda", "warp-cpu") the dense
    kernels are cheaper than the host-driven searches for few frequencies (H100, new frames, catalogue at 30 cm:
    two-frequency BP 792 ms with the coarse ROI and coarse-to-fine search against 41 ms for the whole volume; 2FSK
    d05 18.5 ms with `fsk_keep` against 9.9 ms; 3FSK 21.8 against 16.5 ms; two-frequency BP with the coarse ROI
    evaluated as the dense volume over its bounding box, bp._box_depth_m, 54.8 against 40.5 ms), so there only
    `mask_bb` stays on for them; BP with many frequencies keeps the coarse ROI and the search (145 against 519 ms,
    docs/measurements/gpu.md). Where the backend runs `fsk_keep` inside its device graph (`keeps_on_device`: Warp on
    CUDA) it pays and is on, as on the CPU (H100, catalogue at 30 cm: 2FSK d05 0.80-0.88 against 0.88-0.94 ms, 3FSK
    1.09-1.22 against 1.27-1.31 ms, 100 % of depths within 0.1 mm, 2 of 11 806 pixels lost once;
    docs/measurements/formation.md). On every Warp backend (CPU and CUDA) two-frequency BP searches its depths on
    a dense coarse volume (`bp_dense_z_search`: about 4x faster on the H100 with >= 99.995 % of the depths within
    0.1 mm of the dense volume's; runtime against error in docs/measurements/formation.md section 5). The table
    per backend: docs/measurements/skips.md "Defaults"."""
    if method == "bp":
        if dense_beats_search and n_freqs <= 3:
            return SkipSettings(mask_bb=True, bp_dense_z_search=n_freqs == 2)
        # local depth windows where the profiles are sharp (many frequencies; measured on BP_max: formation.md 8)
        # the vertex jump where the profiles are smooth over a coarse step (few frequencies; formation.md 11)
        return SkipSettings(mask_bb=True, coarse_roi=True, bp_coarse_to_fine=True, bp_range_cpu=True,
                            search_local_z=n_freqs >= LOCAL_Z_MIN_FREQS,
                            search_vertex_jump=n_freqs < LOCAL_Z_MIN_FREQS)
    if dense_beats_search:
        return SkipSettings(mask_bb=True, fsk_keep=keeps_on_device)
    return SkipSettings(mask_bb=True, fsk_keep=True)


def resolve(roi: str | Mapping | SkipSettings | None, method: str = "bp", n_freqs: int = 2,
            dense_beats_search: bool = False, keeps_on_device: bool = False) -> SkipSettings:
    """SkipSettings from a preset name ('none', 'auto' = `default_for(method, n_freqs, dense_beats_search,
    keeps_on_device)`, 'all'), a
    mapping of
    fields (a Hydra `roi` config; its `name` key is ignored, an optional `preset` key gives the base, default
    'none'), an instance, or None (= 'auto')."""
    if roi is None:
        roi = "auto"
    if isinstance(roi, SkipSettings):
        return roi
    if isinstance(roi, str):
        if roi not in PRESETS:
            raise ValueError(f"roi must be one of {', '.join(PRESETS)} or a mapping of skip settings, got {roi!r}")
        return {"none": NONE, "all": ALL}.get(roi) or default_for(method, n_freqs, dense_beats_search,
                                                                  keeps_on_device)
    fields = {k: v for k, v in dict(roi).items() if k not in ("name", "preset")}
    known = {f.name for f in dataclasses.fields(SkipSettings)}
    unknown = set(fields) - known
    if unknown:
        raise ValueError(f"unknown roi setting(s) {', '.join(sorted(unknown))}; allowed: {', '.join(sorted(known))}")
    return dataclasses.replace(resolve(dict(roi).get("preset", "none"), method, n_freqs, dense_beats_search,
                                       keeps_on_device), **fields)
