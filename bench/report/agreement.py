"""`python -m bench.report.agreement [--preset realistic] [--out DIR] [--catalogue demo|full] [--objects ...]
[--cells ...] [--ablation]`:
how far the synthetic benchmark is from the paper's real-data Tables II and III.

1. Generates the catalogue at 30 cm with the preset (bench.synth; cached under `--out`/data/<preset>), runs every
   cell of the paper's Tables II (MM-2FSK x 6 configurations, photogrammetry prior) and III (13 cells, and the depth
   camera alone, `prior_only_d10`) under each metric profile of `--profiles` (default: sound and faithful, side by
   side) through `bench.harness.app.run` (finished cells come from the result store `--store`), and writes
   `--out`/agreement.md, like with like: within each table and profile every mean is over the captures all its
   cells count (bench.report.tables), relations are paired per capture. First the paper's stated relations
   (Section IV.C and the RealSense prior's cost), each holding or reversed with both means, in how many captures
   and the paired p-value; what the radar adds over the depth camera alone; then the synthetic tables beside the
   paper's (MM-2FSK.txt, Tables II and III), geometry-fixed cells marked § (scalar-prior cells that cannot reach
   the object from 0.40 m: their error is the geometry's), how many cells lie within a factor 2 (P alone and all
   metrics, § left out), the ordering of the methods per metric against the paper's (Kendall's tau), the prior's
   cost per metric, and per capture where the object sits against 2FSK/3FSK's unambiguous windows around the 0.40 m
   prior (bench.report.placement) and how far the RealSense prior lies from the ground truth (`prior_errors`: the
   share of pixels beyond MM-2FSK Δ10's unambiguous correction, where it must wrap).
2. `--ablation` adds one table: the realistic preset with one effect switched off at a time (bench.synth.config.
   EFFECTS) and each opt-in effect switched on (OPT_IN_EFFECTS), on `--ablation-objects` with 21 frequencies
   (72-82 GHz in 0.5 GHz steps, which holds every two-frequency configuration of Table III exactly) and the cells
   `--ablation-cells` (no BP_max: it needs 128).
3. `--from-results DIR [--faithful-results DIR2] [--data ROOT]`: the same report from finished sweeps' rows
   (DIR/table2, DIR/table3; DIR2 the same sweeps with profile=faithful), without running a method; with the
   sweeps' captures under ROOT also the placement and prior-error sections (the demo does this).

Every cell runs on its own grid as the demo does (BP: the paper's 301 x 301 x 201, configs/cell/). Costs are in
docs/measurements/agreement.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import re
import time
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from bench import cli
from bench.report import scoring, tables, uncertainty

PAPER_METRICS = ["C_g_cm", "C_s_cm", "P_cm", "P_e_cm"]
# MM-2FSK.txt, Table II (photogrammetry prior, 45 objects at 30 cm): C_g, C_s, P, P_e in cm
PAPER_TABLE2 = {"d05": (0.72, 2.14, 2.15, 1.69), "d1": (0.74, 1.26, 1.74, 1.44), "d2": (0.57, 0.60, 0.77, 0.70),
                "d4": (0.53, 0.35, 0.41, 0.37), "d8": (0.54, 0.22, 0.24, 0.21), "d10": (0.51, 0.18, 0.19, 0.17)}
# MM-2FSK.txt, Table III (RealSense prior for MM-2FSK, scalar prior for 2FSK/3FSK, none for BP)
PAPER_TABLE3 = {
    "bp_full": (0.82, 0.90, 0.94, 0.85), "bp_d05": (0.69, 4.27, 3.34, 3.18), "bp_d1": (0.79, 5.29, 3.70, 3.40),
    "bp_d10": (1.02, 6.35, 4.98, 4.87), "2fsk_d05": (0.90, 2.36, 2.55, 2.10), "2fsk_d1": (8.68, 12.27, 12.87, 12.82),
    "2fsk_d10": (9.80, 9.69, 10.38, 10.38), "3fsk_d05_d10": (0.83, 2.54, 2.63, 2.30),
    "3fsk_d1_d10": (8.37, 12.47, 12.88, 12.87), "3fsk_d2_d10": (6.43, 7.90, 8.51, 8.52),
    "mm2fsk_d05": (0.95, 2.95, 3.13, 2.39), "mm2fsk_d1": (0.98, 2.72, 2.84, 2.28), "mm2fsk_d10": (0.82, 1.74, 1.36,
                                                                                                  1.01)}
# pairs the paper's text states (Section IV.C): (better, worse, metric)
PAPER_PAIRS = [("bp_full", "mm2fsk_d10", "P_cm"), ("2fsk_d05", "mm2fsk_d05", "P_cm"),
               ("mm2fsk_d10", "bp_d10", "P_cm"), ("mm2fsk_d10", "2fsk_d10", "P_cm"),
               ("mm2fsk_d1", "2fsk_d1", "P_cm"), ("mm2fsk_d10", "3fsk_d05_d10", "P_cm")]
# BP is left out of the ablation: bp_d05 took 272 s on 4 captures at load ~6 (as much as 15 variants' MM-2FSK)
ABLATION_CELLS = ("mm2fsk_d10", "mm2fsk_d10@photogrammetry", "mm2fsk_d1", "mm2fsk_d05", "2fsk_d05")
ABLATION_FREQUENCY_POINTS = 21


def cell_overrides(cell: str) -> list[str]:
    """Hydra overrides of a cell name: `mm2fsk_d10` (configs/cell/) or `mm2fsk_d10@photogrammetry` (Table II)."""
    method, freq, prior = split_cell(cell)
    if prior:
        return [f"method={method}", f"freq={freq}", f"prior={prior}"]
    return [f"cell={cell}"]


def run_cells(root: Path, cells: list[str], objects: list[str], store: Path | None, out: Path,
              profile: str = "sound") -> pd.DataFrame:
    """Rows of every cell on the captures `<root>/<object>/30` (bench.harness.app.run, timing 'parallel') under
    the metric profile `profile` (configs/profile/)."""
    from hydra import compose, initialize_config_dir

    from bench.harness.app import CONFIG_DIR, run

    frames = []
    for cell in cells:
        overrides = ["dataset=maroon", f"dataset.root={root}",
                     f"dataset.captures=[{','.join(o + '/30' for o in objects)}]",
                     f"store.dir={store if store is not None else 'null'}", f"profile={profile}",
                     *cell_overrides(cell)]
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
            cfg = compose(config_name="config", overrides=overrides)
        started = time.perf_counter()
        rows = pd.DataFrame(run(cfg, out / "runs" / profile / cell.replace("@", "_"), timing="parallel"))
        rows["cell"] = cell
        frames.append(rows)
        print(f"  {cell} ({profile}): {len(rows)} captures, {time.perf_counter() - started:.0f} s", flush=True)
    return pd.concat(frames, ignore_index=True)


def generate(root: Path, config, objects: list[str]) -> float:
    """Generate (or find cached) the captures at 30 cm; returns the seconds spent."""
    from bench.synth import generate_catalogue

    started = time.perf_counter()
    generate_catalogue(root, [30], objects, config)
    return time.perf_counter() - started


PROFILES = ("sound", "faithful")          # configs/profile/: ours, and MAROON's reference definitions
BASELINE_CELL = "prior_only_d10"          # the depth camera alone (examples/prior_only.py), no paper value


def split_cell(cell: str) -> tuple[str, str, str]:
    """(method, freq, prior suffix) of a cell name: 'mm2fsk_d10@photogrammetry' -> ('mm2fsk', 'd10',
    'photogrammetry'), 'prior_only_d10' -> ('prior_only', 'd10', ''), '3fsk_d05_d10' -> ('3fsk', 'd05_d10', '')."""
    from methods.ops.frequencies import CONFIGS_GHZ

    name, _, prior = cell.partition("@")
    for freq in sorted(CONFIGS_GHZ, key=len, reverse=True):
        if name.endswith(f"_{freq}"):
            return name[:-len(freq) - 1], freq, prior
    raise ValueError(f"cell {cell!r}: no frequency configuration at its end")


def geometry_fixed(cell: str, distance_cm: float = 30.0) -> bool:
    """Whether a cell's error is set by the scene's geometry rather than by the method: a scalar-prior cell (2FSK,
    3FSK from 0.40 m) whose coarse pair cannot reach an object at `distance_cm` without wrapping
    (bench.report.placement's window), so its error sits near the prior's distance to the object whatever the
    method does."""
    from bench.report.placement import windows_m
    from methods.domain.radar import MAROON_FREQS_HZ

    method, freq, _ = split_cell(cell)
    if method not in ("2fsk", "3fsk"):
        return False
    coarse = freq.split("_")[0]
    near_m, far_m = windows_m(MAROON_FREQS_HZ, [coarse])[coarse]
    return not near_m <= distance_cm / 100 <= far_m


def profile_of(rows: pd.DataFrame) -> pd.Series:
    """Per row its metric profile: the `metrics` column ('sound' or 'faithful'), 'sound' where absent."""
    if "metrics" not in rows:
        return pd.Series("sound", index=rows.index)
    return rows["metrics"].fillna("sound").astype(str)


def scored(rows: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(summary indexed by cell, paired comparisons with cells as `a`, `b`) of rows with a `cell` column, all
    cells compared on the same captures (bench.report.tables)."""
    summary = tables.summarise(rows)
    cell_of = {(m, f, p): c for m, f, p, c in zip(rows.method, rows.freq, rows.prior, rows.cell, strict=True)}
    if len(set(cell_of.values())) < rows.cell.nunique():
        raise ValueError(f"cells {', '.join(sorted(set(rows.cell)))}: two of them have the same method, frequency "
                         "configuration and prior (a Table II sweep run without the photogrammetry prior?)")
    cells = [cell_of[(m, f, p)] for m, f, p in zip(summary.method, summary.freq, summary.prior, strict=True)]
    by_row = dict(zip(summary.row, cells, strict=True))
    pairs = tables.paired_comparisons(rows)
    pairs["a"], pairs["b"] = pairs.a.map(by_row), pairs.b.map(by_row)
    return summary.set_index(pd.Index(cells, name="cell")), pairs


def means(rows: pd.DataFrame) -> pd.DataFrame:
    """Per cell: the metrics' means (with `_low`, `_high`, `_n`), `failed` and `captures`, every cell over the
    captures all of them count (bench.report.tables' rule)."""
    return scored(rows)[0]


def _capture_names(rows: pd.DataFrame) -> pd.Series:
    return rows.object.astype(str) + " " + rows.distance.astype(str)


def _reconstructed_by_all(rows: pd.DataFrame) -> set[str]:
    """The captures (bench.report.scoring names) every cell of the rows reconstructed."""
    outcome = scoring.outcomes(rows)
    return set(scoring.common_captures(scoring.metric_matrix(outcome, "P_cm")))


def views(rows: pd.DataFrame) -> dict[tuple[str, str], tuple[pd.DataFrame, pd.DataFrame]]:
    """`scored` per (profile, paper table 'II' or 'III') present in the rows. Where both profiles are present, a
    table's means and pairs of both are over the same captures: those every cell reconstructed under every
    profile; `failed` still counts each profile's own failures."""
    found = {}
    profile = profile_of(rows)
    in_table2 = rows.cell.str.endswith("@photogrammetry")
    for table, mask in (("II", in_table2), ("III", ~in_table2)):
        parts = {name: rows[(profile == name) & mask] for name in PROFILES if ((profile == name) & mask).any()}
        if len(parts) < 2:
            found.update({(name, table): scored(part) for name, part in parts.items()})
            continue
        shared = set.intersection(*(_reconstructed_by_all(part) for part in parts.values()))
        for name, part in parts.items():
            whole = scored(part)[0]
            summary, pairs = scored(part[_capture_names(part).isin(shared)])
            summary[["failed", "captures"]] = whole.loc[summary.index, ["failed", "captures"]]
            found[(name, table)] = summary, pairs
    return found


def _relation(label: str, paper: tuple[float, float], results: list[str]) -> str:
    return f"{label} (paper {paper[0]:.2f} vs {paper[1]:.2f} cm): " + ("; ".join(results) or "not run here")


def relations(found: dict, labels: dict) -> list[str]:
    """The paper's stated relations (PAPER_PAIRS, Section IV.C), each per profile: holds or reversed, with both
    means on the same captures and the paired count and p-value."""
    lines = []
    for better, worse, metric in PAPER_PAIRS:
        index, name = PAPER_METRICS.index(metric), metric.removesuffix("_cm")
        results = []
        for profile in PROFILES:
            if (profile, "III") not in found:
                continue
            summary, pairs = found[(profile, "III")]
            if better not in summary.index or worse not in summary.index:
                continue
            a, b = summary.loc[better, metric], summary.loc[worse, metric]
            paired = tables.pair_of(pairs, metric, better, worse)
            count = (f"; {labels[better]} better in {paired[1]} of {paired[0]} captures, "
                     f"p {uncertainty.p_text(paired[3])}" if paired else "")
            results.append(f"{profile}: {'holds' if a < b else 'reversed'} ({a:.2f} vs {b:.2f} cm{count})")
        lines.append(_relation(f"{labels[better]} < {labels[worse]} on {name}",
                               (PAPER_TABLE3[better][index], PAPER_TABLE3[worse][index]), results))
    return lines


def prior_cost(rows: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """MM-2FSK with the RealSense prior over the photogrammetry prior, per profile, configuration and metric, each
    pair of cells on the captures both reconstructed; and the paper's relation (the RealSense prior costs: ratio
    above 1) per configuration, paired."""
    lines, stated = [], []
    profile = profile_of(rows)
    for freq in ("d05", "d1", "d10"):
        real, ground = f"mm2fsk_{freq}", f"mm2fsk_{freq}@photogrammetry"
        line = {"configuration": tables.row_label("mm2fsk", freq)}
        results = []
        for name in PROFILES:
            part = rows[(profile == name) & rows.cell.isin([real, ground])]
            if set(part.cell) != {real, ground}:
                continue
            summary, pairs = scored(part)
            for metric in PAPER_METRICS:
                line[f"{metric.removesuffix('_cm')} {name}"] = summary.loc[real, metric] / summary.loc[ground, metric]
            line[f"captures {name}"] = int(summary.loc[real, "P_cm_n"])
            paired = tables.pair_of(pairs, "P_cm", ground, real)
            results.append(f"{name}: {'holds' if line[f'P {name}'] > 1 else 'reversed'} (x{line[f'P {name}']:.2f}"
                           + (f"; the ground-truth prior better in {paired[1]} of {paired[0]} captures, p "
                              f"{uncertainty.p_text(paired[3])})" if paired else ")"))
        if len(line) == 1:
            continue
        for index, metric in enumerate(PAPER_METRICS):
            line[f"{metric.removesuffix('_cm')} paper"] = PAPER_TABLE3[real][index] / PAPER_TABLE2[freq][index]
        lines.append(line)
        stated.append(f"{line['configuration']}: the RealSense prior costs on P, Table III / Table II > 1 (paper "
                      f"x{line['P paper']:.2f}): " + "; ".join(results))
    return pd.DataFrame(lines), stated


def comparison(found: dict, table: str, paper: dict, labels: dict) -> pd.DataFrame:
    """Per cell of paper table `table` ('II' or 'III'; keys as in `paper`), the synthetic means of every profile
    beside the paper's; geometry-fixed cells marked §; the depth camera alone after Table III's cells."""
    keys = list(paper) + ([BASELINE_CELL] if table == "III" else [])
    profiles = [p for p in PROFILES if (p, table) in found]
    lines = []
    for key in keys:
        cell = f"mm2fsk_{key}@photogrammetry" if table == "II" else key
        present = {p: found[(p, table)][0] for p in profiles if cell in found[(p, table)][0].index}
        if not present:
            continue
        line = {"cell": labels.get(key, key) + (" §" if geometry_fixed(cell) else ""),
                f"failed ({' / '.join(profiles)})": " / ".join(
                    f"{present[p].loc[cell, 'failed']}/{present[p].loc[cell, 'captures']}" if p in present else "–"
                    for p in profiles)}
        for index, metric in enumerate(PAPER_METRICS):
            name = metric.removesuffix("_cm")
            for profile in profiles:
                line[f"{name} {profile}"] = present[profile].loc[cell, metric] if profile in present else np.nan
            line[f"{name} paper"] = paper[key][index] if key in paper else float("nan")
        lines.append(line)
    return pd.DataFrame(lines)


def within_two(table: pd.DataFrame) -> list[str]:
    """Per profile: how many cells of `comparison` tables lie within a factor 2 of the paper, on P alone and on
    all four metrics, the geometry-fixed cells (§) left out; then the cells outside."""
    lines = []
    flagged = table.cell.str.endswith(" §")
    for profile in PROFILES:
        if f"P {profile}" not in table:
            continue
        kept = table[~flagged & table["P paper"].notna()]
        ratios = {m: kept[f"{m.removesuffix('_cm')} {profile}"] / kept[f"{m.removesuffix('_cm')} paper"]
                  for m in PAPER_METRICS}
        inside = {m: ((r >= 0.5) & (r <= 2.0)) for m, r in ratios.items()}
        total = int(sum(v.sum() for v in inside.values()))
        outside = [f"{c} {m.removesuffix('_cm')} x{r:.2f}" for m in PAPER_METRICS
                   for c, r, ok in zip(kept.cell, ratios[m], inside[m], strict=True) if not ok]
        n_flagged = int(flagged.sum())
        lines.append(f"{profile}: P within 2x in {int(inside['P_cm'].sum())} of {len(kept)} cells; all four metrics "
                     f"{total} of {4 * len(kept)} ({n_flagged} geometry-fixed cells §, {4 * n_flagged} values, left "
                     "out). Outside: "
                     + (", ".join(outside) or "none"))
    return lines


def orderings(summary: pd.DataFrame, paper: dict, labels: dict) -> pd.DataFrame:
    """Per metric: Kendall's tau between the synthetic and the paper's ranking of the cells, and the best cell of
    each (means on the same captures, `means`)."""
    keys = [k for k in paper if k in summary.index]
    lines = []
    for index, metric in enumerate(PAPER_METRICS):
        ours = np.array([summary.loc[k, metric] for k in keys])
        theirs = np.array([paper[k][index] for k in keys])
        tau = stats.kendalltau(ours, theirs).statistic if len(keys) > 1 else float("nan")
        lines.append({"metric": metric.removesuffix("_cm"), "Kendall tau": tau,
                      "best (synthetic)": labels[keys[int(np.nanargmin(ours))]],
                      "best (paper)": labels[keys[int(np.argmin(theirs))]],
                      "synthetic order": " < ".join(labels[keys[i]] for i in np.argsort(ours)),
                      "paper order": " < ".join(labels[keys[i]] for i in np.argsort(theirs))})
    return pd.DataFrame(lines)


def labels_of(cells: list[str]) -> dict:
    """Row labels of cell names (bench.report.tables.row_label), '(photogrammetry)' after Table II's; the paper's
    cells (PAPER_TABLE2 keys are configurations) and the depth camera alone always included."""
    out = {}
    for cell in [*cells, *PAPER_TABLE3, BASELINE_CELL]:
        method, freq, prior = split_cell(cell)
        label = "Prior only" if method == tables.BASELINE_METHOD else None
        out[cell] = tables.row_label(method, freq, label) + (f" ({prior})" if prior else "")
    out.update({f: tables.row_label("mm2fsk", f) + " (photogrammetry)" for f in PAPER_TABLE2})
    return out


# The camera's error budget at its sources' bounds (bench/synth/README.md): the depth scale at the D400 data sheet's
# 2 % and the calibration residual at twice Wirth et al.'s millimetre level. Not a fit: what the paper's prior cost
# (7.2 on P) would ask of the camera beyond them.
CAMERA_BOUNDS = {
    "all effects on": {},
    "depth scale 2 % (data sheet bound)": {"depth_scale_error": 0.02},
    "calibration 6 mm / 1.0°": {"extrinsic_error_mm": 6.0, "extrinsic_error_deg": 1.0},
    "both": {"depth_scale_error": 0.02, "extrinsic_error_mm": 6.0, "extrinsic_error_deg": 1.0},
}
CAMERA_BOUNDS_CELLS = ("mm2fsk_d10", "mm2fsk_d10@photogrammetry")


def variants_table(config, variants: dict[str, dict], column: str, objects: list[str], cells: list[str],
                   store: Path | None, out: Path) -> pd.DataFrame:
    """P (cm) per cell for each variant of `config` (name -> settings replaced), on a reduced frequency grid; plus
    the prior cost at Δ10 where both MM-2FSK Δ10 cells ran (columns: the cells' labels; MM-2FSK without a prior
    named runs on the RealSense prior). Variants of the same name share their captures."""
    labels = labels_of(cells)
    lines = []
    for name, change in variants.items():
        variant = dataclasses.replace(config, frequency_points=ABLATION_FREQUENCY_POINTS, **change)
        slug = re.sub(r"[^\w.-]+", "_", name).strip("_")
        seconds = generate(out / "ablation" / slug, variant, objects)
        print(f"ablation '{name}': data {seconds:.0f} s", flush=True)
        summary = means(run_cells(out / "ablation" / slug, cells, objects, store, out / "ablation_runs" / slug))
        line = {column: name}
        line.update({labels[cell]: summary.loc[cell, "P_cm"] for cell in cells if cell in summary.index})
        if {"mm2fsk_d10", "mm2fsk_d10@photogrammetry"} <= set(summary.index):
            line["prior cost d10"] = summary.loc["mm2fsk_d10", "P_cm"] / summary.loc["mm2fsk_d10@photogrammetry",
                                                                                      "P_cm"]
        lines.append(line)
    return pd.DataFrame(lines)


def paper_row(cells: list[str], column: str) -> dict:
    """The paper's P (cm) of `cells` and its prior cost at Δ10, as one line of a `variants_table`."""
    labels, line = labels_of(cells), {column: "paper (45 MAROON objects, 128 frequencies)"}
    for cell in cells:
        name, _, prior = cell.partition("@")
        line[labels[cell]] = (PAPER_TABLE2[name.split("_", 1)[1]] if prior else PAPER_TABLE3[name])[2]
    if {"mm2fsk_d10", "mm2fsk_d10@photogrammetry"} <= set(cells):
        line["prior cost d10"] = PAPER_TABLE3["mm2fsk_d10"][2] / PAPER_TABLE2["d10"][2]
    return line


def with_paper_row(table: pd.DataFrame, cells: list[str]) -> pd.DataFrame:
    """A `variants_table` of `cells` with the paper's line appended."""
    return pd.concat([table, pd.DataFrame([paper_row(cells, table.columns[0])])], ignore_index=True)


def ablation(config, objects: list[str], cells: list[str], store: Path | None, out: Path) -> pd.DataFrame:
    """`variants_table` with the preset, each effect off (EFFECTS) and each opt-in effect on (OPT_IN_EFFECTS)."""
    from bench.synth.config import EFFECTS, OPT_IN_EFFECTS

    variants = {"all effects on": {}, **EFFECTS, **{f"(on) {name}": on for name, on in OPT_IN_EFFECTS.items()}}
    return variants_table(config, variants, "effect off (or on)", objects, cells, store, out)


def prior_errors(root: Path, objects: list[str]) -> pd.DataFrame:
    """Per capture at 30 cm: the RealSense prior against the photogrammetry prior on the radar pixels both cover:
    median and mean |error| (mm) and the share beyond MM-2FSK's maximum unambiguous correction at the frame's
    Δ10 pair (about 7.5 mm), where MM-2FSK Δ10 must wrap: what the paper's prior cost (7.2x on P) asks of the data."""
    from bench.maroon.reader import read_capture
    from methods.api import frequency_indices, prior_image_m
    from methods.ops.frequencies import max_unambiguous_depth_m

    lines = []
    for name in objects:
        capture = read_capture(root / name / "30", parts=("radar", "realsense", "mesh"))
        grid, freqs_hz = capture.radar.grid, capture.radar.freqs_hz
        pair = freqs_hz[frequency_indices(freqs_hz, "d10")]
        limit_m = max_unambiguous_depth_m(float(np.ptp(pair)))
        camera = np.asarray(prior_image_m(capture, "realsense", grid))
        truth = np.asarray(prior_image_m(capture, "photogrammetry", grid))
        both = np.isfinite(camera) & np.isfinite(truth)
        error_mm = (camera - truth)[both] * 1e3
        lines.append({"capture": name, "pixels": int(both.sum()), "median error mm": float(np.median(error_mm)),
                      "mean |error| mm": float(np.mean(np.abs(error_mm))),
                      f"share beyond {limit_m * 1e3:.1f} mm": float(np.mean(np.abs(error_mm) > limit_m * 1e3))})
    return pd.DataFrame(lines)


def _markdown(frame: pd.DataFrame) -> str:
    return tables.to_markdown(frame) if len(frame) else "(no cells)"


def cells_of_sweeps(table2: pd.DataFrame | None, table3: pd.DataFrame | None) -> pd.DataFrame:
    """The rows of a demo's (or any) table2 and table3 sweeps at 30 cm with this module's `cell` names: Table II rows
    become `mm2fsk_<freq>@photogrammetry`, Table III rows `<method>_<freq>` (e.g. `bp_full`, `3fsk_d05_d10`)."""
    frames = []
    for rows, suffix in ((table2, "@photogrammetry"), (table3, "")):
        if rows is None or not len(rows):
            continue
        rows = rows[rows["distance"].astype(int) == 30].copy()
        rows["cell"] = rows["method"].astype(str) + "_" + rows["freq"].astype(str) + suffix
        frames.append(rows)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["cell", *PAPER_METRICS])


def _bullets(lines: list[str]) -> str:
    return "\n".join(f"* {line}" for line in lines) or "(none of its cells here)"


def radar_over_camera(rows: pd.DataFrame) -> list[str]:
    """Per profile, the best radar row of Table III on P against the depth camera alone (bench.report.verdict)."""
    from bench.report import verdict

    lines = []
    profile = profile_of(rows)
    for name in PROFILES:
        part = rows[(profile == name) & ~rows.cell.str.endswith("@photogrammetry")]
        if BASELINE_CELL not in set(part.cell):
            continue
        head, *found = verdict.baseline_lines(tables.summarise(part), tables.paired_comparisons(part))
        lines += [f"{name}: {line}" for line in found]
    return lines


def report(rows: pd.DataFrame, preset_name: str, objects: list[str]) -> list[str]:
    """Markdown sections comparing the rows (with a `cell` column; a `metrics` column telling the profile) to the
    paper's Tables II and III, like with like: within each table and profile every mean is over the captures all
    its cells count, relations are paired per capture, both profiles side by side."""
    labels = labels_of(sorted(set(rows.cell)))
    found = views(rows)
    table2 = comparison(found, "II", PAPER_TABLE2, {f: labels[f] for f in PAPER_TABLE2})
    table3 = comparison(found, "III", PAPER_TABLE3, labels)
    cost, cost_relations = prior_cost(rows)
    present = [p for p in PROFILES if any(key[0] == p for key in found)]
    missing = [p for p in PROFILES if p not in present]
    n = {key: int(summary.P_cm_n.max()) for key, (summary, _) in found.items()}
    counts = "; ".join(f"Table {t} ({p}): P over {n[(p, t)]} captures" for p, t in sorted(n))
    not_run = (f"; not run here: {', '.join(missing)} (python -m bench.report.agreement --profiles sound faithful, "
               "or --faithful-results DIR)" if missing else "")
    orders = [part for p in present if (p, "III") in found
              for part in (f"\n{p}:\n", _markdown(orderings(found[(p, "III")][0], PAPER_TABLE3, labels)))]
    return [f"# Paper agreement: synthetic preset `{preset_name}` against MM-2FSK Tables II and III\n",
            f"Captures: {', '.join(objects)} at 30 cm (paper: 45 MAROON objects at 30 cm). Metrics in cm. Like "
            f"with like: within each table and profile every mean is over the captures all its cells count "
            f"(bench.report.tables: P where every cell reconstructed the capture; with both profiles, where every "
            f"cell did under both; {counts}); relations are paired per capture. Profiles: sound (ours) and faithful "
            f"(MAROON's reference definitions, which the paper follows)" + not_run + ". § marks a geometry-fixed "
            "cell: a scalar-prior cell whose coarse pair cannot reach the object at 30 cm from the 0.40 m prior, so "
            "its error is the prior's distance to the object whatever the method does.",
            "\n## The paper's stated relations (Section IV.C)\n", _bullets(relations(found, labels) + cost_relations),
            "\n## What the radar adds over the depth camera alone (not in the paper)\n",
            _bullets(radar_over_camera(rows)),
            "\n## Table II (MM-2FSK, photogrammetry prior)\n", _markdown(table2),
            "\n## Table III\n", _markdown(table3),
            "\n## Within a factor 2 of the paper\n", _bullets(within_two(pd.concat([table2, table3]))),
            "\n## Ordering of the Table III cells per metric\n", *orders,
            "\n## RealSense prior's cost (MM-2FSK, Table III / Table II, each pair on the captures both "
            "reconstructed)\n", _markdown(cost)]


def capture_sections(root: Path, objects: list[str], rows: pd.DataFrame | None = None) -> list[str]:
    """Markdown sections measured on the captures `<root>/<object>/30`: where each object sits against the
    scalar-prior windows (bench.report.placement, with the rows' P per capture) and the RealSense prior's error."""
    from bench.report.placement import placement

    return ["\n## Placement against the scalar prior's windows (2FSK/3FSK start from 0.40 m)\n",
            _markdown(placement(root, objects, rows)),
            "\nShare = pixels of the visible ground-truth surface on the radar grid inside the window the first "
            "pass corrects without wrapping; P = the capture's P in the sweep. An object inside the window whose P "
            "is near the window's width wrapped anyway: its first pass took a reference pixel whose phase the "
            "clutter and the mount pulled over the edge.",
            "\n## The RealSense prior against the ground truth (what MM-2FSK Δ10 has to correct)\n",
            _markdown(prior_errors(root, objects))]


def write_from_sweeps(table2: pd.DataFrame | None, table3: pd.DataFrame | None, path: Path,
                      preset_name: str, data_root: Path | None = None,
                      faithful: tuple[pd.DataFrame | None, pd.DataFrame | None] = (None, None)) -> Path | None:
    """`path` (agreement.md) from the rows of finished table2/table3 sweeps (and `faithful`: the same sweeps run
    with profile=faithful), no method run; with `data_root` (the sweeps' captures) also the sections measured on
    the captures. None (nothing written) when the rows hold no capture at 30 cm."""
    rows = cells_of_sweeps(*(pd.concat([a, b]) if a is not None and b is not None else a if b is None else b
                             for a, b in zip((table2, table3), faithful, strict=True)))
    if not len(rows):
        return None
    objects = sorted(rows["object"].unique())
    sound = rows[profile_of(rows) == "sound"]
    captures = capture_sections(data_root, objects, sound) if data_root is not None else []
    text = "\n".join(report(rows, preset_name, objects) + captures
                     + ["\nFrom the rows of the sweeps (python -m bench.report.agreement --from-results DIR).\n"])
    path.write_text(text)
    return path


def _read_rows(path: Path) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    try:
        return pd.read_csv(path)
    except (OSError, ValueError) as err:
        raise cli.UserError(path, f"not a results table ({err})") from None


def main() -> int:
    from bench.synth import CATALOGUES, FULL_CATALOGUE
    from bench.synth.config import PRESETS, preset

    parser = cli.ArgumentParser(prog="python -m bench.report.agreement", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", choices=list(PRESETS), default="realistic")
    parser.add_argument("--seed", type=int, default=None,
                        help="the generator's seed (noise, residuals, clutter draws; default: the preset's, 0)")
    parser.add_argument("--out", type=Path, default=Path("outputs/agreement"))
    parser.add_argument("--store", type=Path, default=Path("outputs/store"), help="result store; 'none' for none")
    parser.add_argument("--catalogue", choices=list(CATALOGUES), default="demo",
                        help="the objects of --objects and --ablation-objects when not given: demo (8) or full (27)")
    parser.add_argument("--objects", nargs="+", default=None, choices=list(FULL_CATALOGUE))
    parser.add_argument("--cells", nargs="+", default=None,
                        help="subset of the Tables II/III cells, e.g. mm2fsk_d10 mm2fsk_d10@photogrammetry")
    parser.add_argument("--ablation", action="store_true", help="also the one-effect-off table")
    parser.add_argument("--ablation-objects", nargs="+", default=None, choices=list(FULL_CATALOGUE))
    parser.add_argument("--ablation-cells", nargs="+", default=list(ABLATION_CELLS))
    parser.add_argument("--no-tables", action="store_true", help="only the ablation")
    parser.add_argument("--from-results", type=Path, metavar="DIR",
                        help="no computation: the report from DIR/table2/results.csv and DIR/table3/results.csv "
                             "(a demo's --out or results/), written to --out/agreement.md")
    parser.add_argument("--faithful-results", type=Path, metavar="DIR",
                        help="with --from-results: the same sweeps run with profile=faithful (DIR/table2, "
                             "DIR/table3), shown beside the sound profile")
    parser.add_argument("--data", type=Path, metavar="ROOT",
                        help="with --from-results: the sweeps' captures (ROOT/<object>/30), for the placement and "
                             "prior-error sections")
    parser.add_argument("--profiles", nargs="+", choices=list(PROFILES), default=list(PROFILES),
                        help="metric profiles to run the cells under (default: both, side by side)")
    args = parser.parse_args()
    args.objects = args.objects or list(CATALOGUES[args.catalogue])
    args.ablation_objects = args.ablation_objects or list(CATALOGUES[args.catalogue])
    all_cells = [f"mm2fsk_{f}@photogrammetry" for f in PAPER_TABLE2] + list(PAPER_TABLE3) + [BASELINE_CELL]
    cells = all_cells if args.cells is None else args.cells
    unknown = [c for c in cells + args.ablation_cells if c not in all_cells]
    if unknown:
        parser.error(f"unknown cell(s) {', '.join(unknown)}; known: {', '.join(all_cells)}")
    if args.from_results is not None:
        folder = cli.existing_path(args.from_results, "dir", "--from-results")
        out = cli.output_dir(args.out).resolve()
        data = cli.existing_path(args.data, "dir", "--data") if args.data is not None else None
        faithful = (None if args.faithful_results is None else
                    cli.existing_path(args.faithful_results, "dir", "--faithful-results"))
        written = write_from_sweeps(_read_rows(folder / "table2" / "results.csv"),
                                    _read_rows(folder / "table3" / "results.csv"), out / "agreement.md", args.preset,
                                    data, (None, None) if faithful is None else
                                    (_read_rows(faithful / "table2" / "results.csv"),
                                     _read_rows(faithful / "table3" / "results.csv")))
        if written is None:
            raise cli.UserError(folder, "no table2/table3 results.csv with captures at 30 cm")
        print(written.read_text())
        return 0
    out = cli.output_dir(args.out).resolve()
    store = None if str(args.store) == "none" else args.store.resolve()
    config = preset(args.preset) if args.seed is None else preset(args.preset, seed=args.seed)
    started = time.perf_counter()
    name = args.preset if args.seed is None else f"{args.preset}` seed `{args.seed}"
    parts = [f"# Paper agreement: synthetic preset `{name}` against MM-2FSK Tables II and III\n"]
    if not args.no_tables:
        root = out / "data" / args.preset
        print(f"data {root}: {generate(root, config, args.objects):.0f} s", flush=True)
        rows = pd.concat([run_cells(root, cells, args.objects, store, out, profile) for profile in args.profiles],
                         ignore_index=True)
        rows.to_csv(out / "rows.csv", index=False)
        parts = report(rows, name, args.objects) + capture_sections(root, args.objects,
                                                                   rows[profile_of(rows) == "sound"])
    if args.ablation:
        table = with_paper_row(ablation(config, args.ablation_objects, args.ablation_cells, store, out),
                               args.ablation_cells)
        bounds = with_paper_row(variants_table(config, CAMERA_BOUNDS, "camera error", args.ablation_objects,
                                               list(CAMERA_BOUNDS_CELLS), store, out), list(CAMERA_BOUNDS_CELLS))
        parts += [f"\n## Ablation: P (cm) with one effect off, opt-in effects on ({', '.join(args.ablation_objects)}; "
                  f"{ABLATION_FREQUENCY_POINTS} frequencies)\n", _markdown(table),
                  "\n## The camera's errors at their sources' bounds: MM-2FSK Δ10's P (cm) and the prior's cost "
                  "(paper: 7.16)\n", _markdown(bounds)]
    parts.append(f"\n{time.perf_counter() - started:.0f} s in all.")
    text = "\n".join(parts) + "\n"
    (out / "agreement.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
