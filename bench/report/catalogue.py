"""`python -m bench.report.catalogue DIR [--out FILE]`: the paper's stated relations on the full synthetic catalogue,
per generator seed and metric profile, each paired over the captures both compared cells reconstructed, and the
measurements that show why a relation holds or not (issue #27's done-when).

DIR (results/catalogue/, made by scripts/catalogue_evidence.py; its README says how) holds:
* `rows.csv`: every cell of Tables II and III and the depth camera alone (bench.report.agreement's cell names in
  `cell`) per generator seed (`seed`), metric profile (`metrics`) and capture at 30 cm;
* `prior_errors.csv`: per seed and capture the RealSense prior against the ground truth (agreement.prior_errors);
* `ablation.csv` (optional): seed 0 with one effect off at a time (`variant`, bench.synth.config.EFFECTS; the preset
  itself is `all effects on`), the camera's effects on every object, the radar's on a subset (`kind`).

The report (`--out`, default DIR/agreement.md): a table per relation with holds/reversed per seed and profile, the
three seeds' captures pooled beside them, and the paper's numbers; the cells within 2x of the paper per seed; what
drives each relation per object; the camera's error against MM-2FSK Δ10's unambiguous correction; the ablation.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from bench import cli
from bench.report import agreement, scoring, tables, uncertainty

METRICS = agreement.PAPER_METRICS
SEEDS_COLUMN = "seed"
POOLED = "pooled"
MM10, TRUTH10, CAMERA, BP_MAX = "mm2fsk_d10", "mm2fsk_d10@photogrammetry", agreement.BASELINE_CELL, "bp_full"
# cells of two or three frequencies the issue compares MM-2FSK Δ10 with (similar frequency count)
FEW_FREQUENCY = ["bp_d05", "bp_d1", "bp_d10", "2fsk_d05", "2fsk_d1", "2fsk_d10", "3fsk_d05_d10", "3fsk_d1_d10",
                 "3fsk_d2_d10"]
MIN_COST = 4.0            # the issue: the RealSense prior costs MM-2FSK Δ10 at least 4x on P (paper 7.16)
CLEARLY_P = 0.05          # "clearly worse": the paired test's p below this on the metric, and a worse mean


def pooled(rows: pd.DataFrame) -> pd.DataFrame:
    """The seeds' captures as distinct captures (object 'name #seed'), for means and tests over all of them."""
    return rows.assign(object=rows.object.astype(str) + " #" + rows[SEEDS_COLUMN].astype(str))


def groups(rows: pd.DataFrame) -> list[tuple[str, str, pd.DataFrame]]:
    """(profile, seed label, rows) per profile and seed, then per profile the seeds pooled."""
    found = []
    for profile in agreement.PROFILES:
        part = rows[agreement.profile_of(rows) == profile]
        if not len(part):
            continue
        found += [(profile, f"seed {s}", seed_rows) for s, seed_rows in part.groupby(SEEDS_COLUMN)]
        found.append((profile, POOLED, pooled(part)))
    return found


def matrix_of(rows: pd.DataFrame, metric: str) -> pd.DataFrame:
    """`metric` per cell (index) and capture (columns) as bench.report.scoring counts it: P and P_e where the cell
    reconstructed the capture, C_g and C_s wherever defined (no bootstrap: the report makes hundreds of these)."""
    outcome = scoring.outcomes(rows)
    cells = rows.drop_duplicates(scoring.GROUP_COLUMNS).set_index(scoring.GROUP_COLUMNS).cell
    outcome["cell"] = [cells[key] for key in outcome[scoring.GROUP_COLUMNS].itertuples(index=False, name=None)]
    return outcome.pivot(index="cell", columns="capture", values=metric)


def compared(rows: pd.DataFrame, a: str, b: str, metric: str) -> dict | None:
    """Cells `a` and `b` on `metric`, over the captures both count (bench.report.scoring): means, captures, in how
    many each is lower, the paired permutation test's p; None when either cell is missing or counts no capture."""
    part = rows[rows.cell.isin([a, b])]
    if set(part.cell) != {a, b}:
        return None
    matrix = matrix_of(part, metric)
    result = uncertainty.paired(matrix.loc[a], matrix.loc[b])
    if result.n == 0:
        return None
    both = matrix.loc[a].notna() & matrix.loc[b].notna()
    return {"a": matrix.loc[a, both].mean(), "b": matrix.loc[b, both].mean(), "n": result.n,
            "a_better": result.a_better, "b_better": result.b_better, "p": result.p_value}


def _text(result: dict, verdict: str, extra: str = "") -> str:
    return (f"{verdict} {result['a']:.2f} vs {result['b']:.2f}{extra} "
            f"({result['a_better']}/{result['n']}, p {uncertainty.p_text(result['p'])})")


def relation_table(rows: pd.DataFrame) -> pd.DataFrame:
    """One line per (relation, profile): holds or reversed per seed and pooled, with both means (cm), in how many
    captures the first cell is better, the paired p-value, and the paper's numbers. The relations: BP_max against
    MM-2FSK Δ10 on P and P_e, the other pairs the paper's text states (agreement.PAPER_PAIRS), the RealSense prior's
    cost and the depth camera alone (the cells of two or three frequencies on every metric: few_frequency_summary)."""
    labels = agreement.labels_of(sorted(set(rows.cell)))
    specs = [(f"{labels[BP_MAX]} < {labels[MM10]} on {m.removesuffix('_cm')}", BP_MAX, MM10, m, "less")
             for m in ("P_cm", "P_e_cm")]
    specs += [(f"{labels[a]} < {labels[b]} on {m.removesuffix('_cm')}" + (" §" if agreement.geometry_fixed(b) else ""),
               a, b, m, "less") for a, b, m in agreement.PAPER_PAIRS if a != BP_MAX]
    specs += [(f"prior cost {labels[MM10]} on P >= {MIN_COST:g}x", MM10, TRUTH10, "P_cm", "cost")]
    specs += [(f"camera alone clearly worse than {labels[MM10]} on {m.removesuffix('_cm')}", MM10, CAMERA, m,
               "clearly") for m in ("P_cm", "C_s_cm")]
    lines = []
    for name, a, b, metric, kind in specs:
        index = METRICS.index(metric)
        paper_a = agreement.PAPER_TABLE3[a][index]
        paper_b = (agreement.PAPER_TABLE2["d10"][index] if b == TRUTH10 else
                   agreement.PAPER_TABLE3[b][index] if b in agreement.PAPER_TABLE3 else float("nan"))
        paper = (f"x{paper_a / paper_b:.2f}" if kind == "cost" else
                 f"{paper_a:.2f} vs {paper_b:.2f}" if np.isfinite(paper_b) else "not in the paper")
        line = {"relation": name}
        for profile, seed, part in groups(rows):
            line["profile"] = profile
            result = compared(part, a, b, metric)
            if result is None:
                text = "–"
            elif kind == "cost":
                ratio = result["a"] / result["b"]
                text = (f"{'holds' if ratio >= MIN_COST else 'not met'} x{ratio:.2f} (truth better "
                        f"{result['b_better']}/{result['n']}, p {uncertainty.p_text(result['p'])})")
            elif kind == "clearly":
                verdict = ("reversed" if result["a"] >= result["b"] else "holds" if result["p"] < CLEARLY_P
                           else "not clear")
                text = _text(result, verdict, f" (x{result['b'] / result['a']:.2f})")
            else:
                text = _text(result, "holds" if result["a"] < result["b"] else "reversed")
            line[seed] = text
            if seed == POOLED:
                if any(value != "–" for key, value in line.items() if key not in ("relation", "profile")):
                    lines.append({**line, "paper": paper})
                line = {"relation": name}
    return pd.DataFrame(lines)


def few_frequency_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per cell of FEW_FREQUENCY and profile: on how many of the four metrics MM-2FSK Δ10's mean is lower, per seed
    and pooled (the issue asks for at least three)."""
    labels = agreement.labels_of(sorted(set(rows.cell)))
    lines = []
    for cell in FEW_FREQUENCY:
        for profile in agreement.PROFILES:
            line = {"against": labels[cell] + (" §" if agreement.geometry_fixed(cell) else ""), "profile": profile}
            for prof, seed, part in groups(rows):
                if prof != profile:
                    continue
                results = [compared(part, MM10, cell, m) for m in METRICS]
                if any(r is None for r in results):
                    continue
                wins = [m.removesuffix("_cm") for m, r in zip(METRICS, results, strict=True) if r["a"] < r["b"]]
                line[seed] = f"{'holds' if len(wins) >= 3 else 'not met'} {len(wins)}/4" + (
                    f" (not {', '.join(m.removesuffix('_cm') for m in METRICS if m.removesuffix('_cm') not in wins)})"
                    if len(wins) < 4 else "")
            if len(line) > 2:
                lines.append(line)
    return pd.DataFrame(lines)


def own_means(rows: pd.DataFrame) -> pd.DataFrame:
    """Tables II and III beside the paper's (agreement.comparison's columns), each cell and profile averaged over the
    captures it counts itself (P where it reconstructed them): with 27 objects and the scalar-prior cells failing
    some, the captures every cell reconstructed are a few, which says little about any one cell."""
    labels = {c: label for c, label in agreement.labels_of(sorted(set(rows.cell))).items() if c in set(rows.cell)}
    lines = []
    keys = [(f"mm2fsk_{f}@photogrammetry", agreement.PAPER_TABLE2[f]) for f in agreement.PAPER_TABLE2]
    keys += list(agreement.PAPER_TABLE3.items())
    for cell, paper in keys:
        if cell not in labels:
            continue
        line = {"cell": labels[cell] + (" §" if agreement.geometry_fixed(cell) else "")}
        for profile in agreement.PROFILES:
            part = rows[(rows.cell == cell) & (agreement.profile_of(rows) == profile)]
            if not len(part):
                continue
            for index, metric in enumerate(METRICS):
                line[f"{metric.removesuffix('_cm')} {profile}"] = matrix_of(part, metric).loc[cell].mean()
                line[f"{metric.removesuffix('_cm')} paper"] = paper[index]
            reconstructed = matrix_of(part, "P_cm").loc[cell].notna()
            line[f"failed {profile}"] = f"{int((~reconstructed).sum())}/{reconstructed.size}"
        lines.append(line)
    return pd.DataFrame(lines)


def within_two_per_seed(rows: pd.DataFrame) -> list[str]:
    """agreement.within_two per seed and pooled on `own_means`: the cells of Tables II and III within 2x."""
    return [f"{label}, {line}" for label, part in
            [*((f"seed {s}", r) for s, r in rows.groupby(SEEDS_COLUMN)), (POOLED, pooled(rows))]
            for line in agreement.within_two(own_means(part))]


def per_object(rows: pd.DataFrame, cells: list[str], metric: str = "P_cm") -> pd.DataFrame:
    """Per object and profile: each cell's `metric` averaged over the seeds (NaN where a cell failed every seed)."""
    part = rows[rows.cell.isin(cells)].assign(profile=agreement.profile_of(rows))
    ok = part.failure.astype(object).fillna("").astype(str).eq("")
    part = part.assign(value=part[metric].where(ok))
    table = part.pivot_table(index=["profile", "object"], columns="cell", values="value", aggfunc="mean")
    return table.reindex(columns=cells)


def drivers(rows: pd.DataFrame, better: str, worse: str, metric: str = "P_cm") -> tuple[pd.DataFrame, list[str]]:
    """Which objects drive `better` < `worse` on `metric` (per object over the seeds, sorted by how much `better`
    loses), and per profile how many of the worst objects must go before the pooled relation holds."""
    table = per_object(rows, [better, worse], metric)
    table["difference"] = table[better] - table[worse]
    table = table.sort_values(["profile", "difference"], ascending=[False, False])
    lines = []
    labels = agreement.labels_of(sorted(set(rows.cell)))
    for profile in agreement.PROFILES:
        if profile not in table.index.get_level_values(0):
            continue
        order = table.loc[profile].dropna().index.tolist()
        part = pooled(rows[agreement.profile_of(rows) == profile])
        for k in range(len(order) + 1):
            kept = part[~part.object.str.split(" #").str[0].isin(order[:k])]
            result = compared(kept, better, worse, metric)
            if result is not None and result["a"] < result["b"]:
                lines.append(f"{profile}: {labels[better]} < {labels[worse]} on {metric.removesuffix('_cm')} "
                             f"holds once the {k} objects where it loses most are left out "
                             f"({', '.join(order[:k]) or 'none'}): {result['a']:.2f} vs {result['b']:.2f} cm over "
                             f"{result['n']} captures")
                break
        else:
            lines.append(f"{profile}: it does not hold on any subset of the worst objects")
    return table.reset_index(), lines


def camera_against_range(rows: pd.DataFrame, errors: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """Per object (over the seeds): the RealSense prior's median and mean |error| and share of pixels beyond
    MM-2FSK Δ10's unambiguous correction, beside MM-2FSK Δ10's P with each prior, the prior's cost and the camera
    alone's P; and per profile how the per-capture cost follows the share beyond (Spearman over all captures)."""
    beyond = next(c for c in errors.columns if c.startswith("share beyond"))
    per_capture = errors.rename(columns={"capture": "object"})
    objects = per_capture.groupby("object")[["median error mm", "mean |error| mm", beyond]].mean()
    lines = [f"captures whose prior has its median error beyond {beyond.removeprefix('share beyond ')} (MM-2FSK Δ10's "
             "unambiguous correction): "
             f"{int((per_capture['median error mm'].abs() > float(beyond.split()[2])).sum())} of {len(per_capture)}"
             f"; mean share of pixels beyond: {per_capture[beyond].mean():.2f}"]
    for profile in agreement.PROFILES:
        part = rows[(agreement.profile_of(rows) == profile)]
        if not len(part):
            continue
        values = part[part.cell.isin([MM10, TRUTH10, CAMERA])].pivot_table(
            index=["object", SEEDS_COLUMN], columns="cell", values="P_cm", aggfunc="mean")
        values["cost"] = values[MM10] / values[TRUTH10]
        merged = values.join(per_capture.set_index(["object", SEEDS_COLUMN])[beyond], how="inner").dropna()
        if len(merged) > 2:
            rho = stats.spearmanr(merged[beyond], merged["cost"])
            lines.append(f"{profile}: per capture, the prior's cost against its share of pixels beyond: Spearman "
                         f"{rho.statistic:.2f} (p {uncertainty.p_text(rho.pvalue)}, {len(merged)} captures); cost "
                         f"median {merged['cost'][merged[beyond] < 0.1].median():.2f} where under 10 % of pixels "
                         f"lie beyond, {merged['cost'][merged[beyond] >= 0.5].median():.2f} where half or more do")
        limit_mm = float(beyond.split()[2])
        median = per_capture.set_index(["object", SEEDS_COLUMN])["median error mm"].abs()
        for name, inside in (("within", median <= limit_mm), ("beyond", median > limit_mm)):
            keys = inside[inside].index
            kept = part[part.set_index(["object", SEEDS_COLUMN]).index.isin(keys)]
            result = compared(pooled(kept), MM10, CAMERA, "P_cm")
            if result is not None:
                lines.append(f"{profile}: captures whose prior's median error lies {name} {limit_mm:g} mm: P "
                             f"MM-2FSK Δ10 {result['a']:.2f} vs the camera alone {result['b']:.2f} cm, the radar "
                             f"better in {result['a_better']} of {result['n']} (p {uncertainty.p_text(result['p'])})")
        summary = values.groupby("object")[[MM10, TRUTH10, CAMERA, "cost"]].mean()
        objects = objects.join(summary.add_suffix(f" {profile}"))
    return objects.reset_index(), lines


def ablation_table(ablation: pd.DataFrame, main: pd.DataFrame, kind: str) -> pd.DataFrame:
    """Per effect switched off (and the preset), per profile: the relations' numbers on seed 0's captures of the
    ablation, each pair over the captures both cells count (their number in brackets); camera effects borrow the
    ground-truth-prior cell from the preset (the camera does not change it)."""
    part = ablation[ablation.kind == kind]
    lines = []
    for (variant, profile), rows in part.groupby(["variant", agreement.profile_of(part)], sort=False):
        if kind == "camera":
            objects = set(rows.object)
            truth = main[(main.cell == TRUTH10) & (main[SEEDS_COLUMN] == 0) & main.object.isin(objects)
                         & (agreement.profile_of(main) == profile)]
            rows = pd.concat([rows, truth], ignore_index=True)
        line = {"effect off": variant, "profile": profile}
        pairs = [("P MM-2FSK Δ10 / truth prior (cost)", MM10, TRUTH10, "P_cm"),
                 ("P camera alone / MM-2FSK Δ10", CAMERA, MM10, "P_cm"),
                 ("C_s camera alone / MM-2FSK Δ10", CAMERA, MM10, "C_s_cm"),
                 ("P BP_max / MM-2FSK Δ10", BP_MAX, MM10, "P_cm"), ("P_e BP_max / MM-2FSK Δ10", BP_MAX, MM10, "P_e_cm"),
                 ("P 2FSK Δ0.5 / MM-2FSK Δ10", "2fsk_d05", MM10, "P_cm"),
                 ("P 3FSK / MM-2FSK Δ10", "3fsk_d05_d10", MM10, "P_cm")]
        for name, a, b, metric in pairs:
            result = compared(rows, a, b, metric)
            if result is not None and np.isfinite(result["a"]) and np.isfinite(result["b"]):
                line[name] = (f"{result['a']:.2f} / {result['b']:.2f} = x{result['a'] / result['b']:.2f} "
                              f"({result['n']})")
        lines.append(line)
    return pd.DataFrame(lines)


def _markdown(frame: pd.DataFrame, digits: int = 2) -> str:
    return tables.to_markdown(frame.round(digits)) if len(frame) else "(none)"


def report(folder: Path) -> str:
    """The markdown report of the evidence in `folder` (see the module's docstring)."""
    rows = _read(folder / "rows.csv")
    errors = _read(folder / "prior_errors.csv")
    ablation = _read(folder / "ablation.csv") if (folder / "ablation.csv").is_file() else None
    seeds = sorted(rows[SEEDS_COLUMN].unique())
    objects = sorted(rows.object.unique())
    few, few_lines = few_frequency_summary(rows), []
    bp_table, bp_lines = drivers(rows, BP_MAX, MM10)
    bp_e_table, bp_e_lines = drivers(rows, BP_MAX, MM10, "P_e_cm")
    camera_table, camera_lines = camera_against_range(rows, errors)
    parts = [
        "# The paper's relations on the full synthetic catalogue\n",
        f"{len(objects)} objects at 30 cm, generator seeds {', '.join(map(str, seeds))}, preset `realistic`, 128 "
        "frequencies; both metric profiles. Every relation is paired over the captures both of its cells "
        "reconstructed (bench.report.tables' rule), per seed and with the seeds' captures pooled. A cell reads: "
        "holds/reversed, the first cell's mean vs the second's (cm), in how many captures the first is better of "
        "those both count, and the paired permutation test's p (uncorrected). § marks a geometry-fixed cell "
        f"(bench.report.agreement). 'Clearly worse': a worse mean and p < {CLEARLY_P}.",
        "\n## Relations per seed\n", _markdown(relation_table(rows)),
        "\n## MM-2FSK Δ10 against the cells of two or three frequencies: metrics it wins (of C_g, C_s, P, P_e)\n",
        _markdown(few), *few_lines,
        "\n## Tables II and III, the seeds pooled, each cell over the captures it counts (cm)\n",
        _markdown(own_means(pooled(rows))),
        "\n## Cells within 2x of the paper (each cell over the captures it counts; § cells left out)\n",
        "\n".join(f"* {line}" for line in within_two_per_seed(rows)),
        "\n## What drives BP_max against MM-2FSK Δ10 (per object, P and P_e over the seeds, cm)\n",
        "\n".join(f"* {line}" for line in bp_lines + bp_e_lines), "", _markdown(bp_table),
        "\n## The RealSense prior's error against MM-2FSK Δ10's unambiguous correction (per object over the seeds; "
        "P in cm)\n",
        "\n".join(f"* {line}" for line in camera_lines), "", _markdown(camera_table),
    ]
    if ablation is not None:
        for kind, scope in (("camera", "each camera effect off in turn"), ("radar", "each radar effect off in turn")):
            if (ablation.kind == kind).any():
                names = sorted(ablation[ablation.kind == kind].object.unique())
                parts += [f"\n## Ablation, seed 0: {scope} ({len(names)} objects: {', '.join(names)})\n",
                          _markdown(ablation_table(ablation, rows, kind))]
    return "\n".join(parts) + "\n"


def _read(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise cli.UserError(path, "missing (python -m bench.report.catalogue reads DIR/rows.csv and "
                                  "DIR/prior_errors.csv)")
    try:
        return pd.read_csv(path)
    except (OSError, ValueError) as err:
        raise cli.UserError(path, f"not a results table ({err})") from None


def main() -> int:
    parser = cli.ArgumentParser(prog="python -m bench.report.catalogue", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=Path, help="the evidence (results/catalogue)")
    parser.add_argument("--out", type=Path, default=None, help="the report (default: FOLDER/agreement.md)")
    args = parser.parse_args()
    folder = cli.existing_path(args.folder, "dir", "FOLDER")
    out = args.out or folder / "agreement.md"
    out.write_text(report(folder))
    print(out.read_text())
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
