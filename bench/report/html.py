"""`python -m bench.report SWEEP_ROOT [SWEEP_ROOT ...] [--out FILE] [--no-pictures]`: one HTML page.

It opens with a verdict computed from the tables (bench.report.verdict): per table the best row per metric with
its bootstrap interval and its paired margin over the runner-up, the runtime-against-error front, what the radar
adds over the depth camera alone (where the table has that row) and why any row is marked. Then, for every sweep
root (e.g. `outputs/demo/table2` and `outputs/demo/table3`): the table of means over the captures every row
covers, with intervals, failures and the paired comparisons with the best row (bench.report.tables), the spread
across those captures (median and interquartile range), a per-object view (P per row and capture, failures with
their reasons), the runtime-versus-error plot, the paper-style pictures per capture (bench.report.pictures: point
clouds over the ground truth, depth / magnitude / signed-error panels; PLY files beside them), and per cell its
Hydra overrides, full configuration, code version, device and host. Images are files beside the page (linked by
relative paths: keep the page with its sweep roots), so the page stays small; nothing is loaded from the network.
Default output: `SWEEP_ROOT/report.html` (one root) or `report.html` in the roots' common folder. Pictures are
written under `SWEEP_ROOT/pictures/` (about 1 s of CPU per capture; `--no-pictures` leaves them out); pictures,
plots and the page are redrawn only when their inputs changed (bench.report.keyed).
"""
from __future__ import annotations

import argparse
import html
import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from bench import cli

QUANTILES = (0.25, 0.5, 0.75)
_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em; max-width: 1500px; color: #222; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }
th { background: #f2f2f2; } td:first-child, th:first-child { text-align: left; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.3em 0; }
pre { background: #f7f7f7; padding: 0.5em; font-size: 0.8em; overflow-x: auto; }
.caption { font-size: 0.85em; color: #444; max-width: 1100px; }
nav a { margin-right: 1em; }
"""
# After loading, the page notes on <body> how many of its images decoded (read by tests/bench/report/test_report.py
# through a
# headless browser; a reader sees nothing). No other script, no network access.
_LOADED_CHECK = ("<script>window.addEventListener('load', () => { const images = [...document.images]; "
                 "document.body.dataset.images = images.length; document.body.dataset.imagesLoaded = "
                 "images.filter(i => i.complete && i.naturalWidth > 0).length; });</script>")


def _image(path: Path, alt: str, page_dir: Path) -> str:
    """An <img> of the file at `path`, linked relative to the page's folder."""
    return f'<img alt="{html.escape(alt)}" src="{html.escape(Path(os.path.relpath(path, page_dir)).as_posix())}">'


def _job_dirs(root: Path) -> list[Path]:
    """The sweep's job folders (`<number>_<cell>/` with a results.csv), in job order."""
    jobs = [p.parent for p in root.glob("*/results.csv") if p.parent.name.split("_")[0].isdigit()]
    return sorted(jobs, key=lambda p: int(p.name.split("_")[0]))


def _job_config(job: Path) -> dict:
    path = job / ".hydra" / "config.yaml"
    return yaml.safe_load(path.read_text()) if path.is_file() else {}


def table_name(root: Path) -> str:
    """The table a sweep root holds: its jobs' `report.table` (set by the experiment), else the folder name."""
    for job in _job_dirs(root):
        name = (_job_config(job).get("report") or {}).get("table")
        if name:
            return str(name)
    return root.name


@dataclass(frozen=True)
class Scored:
    """A sweep root's rows scored once for the whole page (the scoring and its bootstrap intervals are most of the
    page's cost outside the pictures): the rows, their summary (bench.report.tables.summarise), the paired
    comparisons and the per-capture outcomes (bench.report.scoring.outcomes)."""
    rows: pd.DataFrame
    summary: pd.DataFrame
    pairs: pd.DataFrame
    outcome: pd.DataFrame

    @classmethod
    def of(cls, rows: pd.DataFrame) -> Scored:
        from bench.report import scoring, tables

        summary, pairs = tables.summary_and_pairs(rows)
        return cls(rows, summary, pairs, scoring.outcomes(rows))


def spread(rows: pd.DataFrame, scored: Scored | None = None) -> pd.DataFrame:
    """Per summary row (bench.report.tables order): failures and, per metric, 'median [q25, q75]' in cm over the
    captures the table's means cover (the interquartile range says how much the captures disagree)."""
    from bench.report import scoring, tables

    scored = scored or Scored.of(rows)
    summary, outcome = scored.summary, scored.outcome
    lines = []
    for _, line in summary.iterrows():
        entry = {"": line.row, "failed": f"{line.failed}/{line.captures}"}
        for metric in tables.METRICS_CM:
            matrix = scoring.metric_matrix(outcome, metric)
            values = matrix.loc[line.row_id, scoring.common_captures(matrix)].dropna()
            name = f"{tables.SHOWN_COLUMNS[metric]} median [IQR]"
            if values.empty:
                entry[name] = "–"
                continue
            q25, q50, q75 = values.quantile(QUANTILES)
            entry[name] = f"{q50:.2f} [{q25:.2f}, {q75:.2f}]"
        lines.append(entry)
    return pd.DataFrame(lines)


def per_object(rows: pd.DataFrame, metric: str = "P_cm", scored: Scored | None = None) -> pd.DataFrame:
    """`metric` (cm) per summary row (lines) and capture (columns 'object distance cm', marked where the table's
    means leave it out), 'failed: <reason>' where the row did not reconstruct the capture (with the metric where
    it is still defined) and 'not run' where it has no result."""
    from bench.report import scoring

    scored = scored or Scored.of(rows)
    summary, outcome = scored.summary, scored.outcome
    matrix = scoring.metric_matrix(outcome, metric)
    common = set(scoring.common_captures(matrix))
    cells = outcome.set_index(["row_id", "capture"])
    table = pd.DataFrame({"": summary.row})
    for capture in sorted(outcome.capture.unique()):
        column = []
        for row_id in summary.row_id:
            cell = cells.loc[(row_id, capture)]
            value = cell[metric]
            if cell.ok:
                column.append(f"{value:.2f}")
            elif cell.reason == scoring.NOT_RUN:
                column.append(scoring.NOT_RUN)
            else:
                kept = f" ({value:.2f})" if np.isfinite(value) else ""
                column.append(f"failed: {cell.reason}{kept}")
        table[f"{capture} cm" + ("" if capture in common else " (not in the means)")] = column
    return table


def _html_table(table: pd.DataFrame) -> str:
    return table.to_html(index=False, escape=True, border=0, na_rep="–")


def _means_table(summary: pd.DataFrame) -> str:
    """The table as bench.report.tables prints it (means with intervals, failures), best values in bold, then the
    paired comparisons with the best row and the failures with their reasons."""
    from bench.report import tables

    shown = tables._formatted(summary, lambda text: f"\x00{text}\x01")
    failures = tables.failures_list(summary)
    return (_html_table(shown).replace("\x00", "<b>").replace("\x01", "</b>")
            + "<p class='caption'>Paired with the best row of each metric, per capture on the captures of the means "
              "(two-sided permutation test, not corrected for the number of comparisons):</p>"
            + _html_table(tables.against_best(summary))
            + ("<p class='caption'>Failures (captures a row did not reconstruct):</p><ul>"
               + "".join(f"<li>{html.escape(line)}</li>" for line in failures) + "</ul>" if failures else ""))


def _cells_section(root: Path, rows: pd.DataFrame) -> str:
    """Per job: cell, overrides, code version(s), device, host, timing, and its full configuration (folded)."""
    parts = ["<table><tr><th>job</th><th>overrides</th><th>code version</th><th>device</th><th>host</th>"
             "<th>timing</th><th>rows</th></tr>"]
    configs = []
    for job in _job_dirs(root):
        job_rows = pd.read_csv(job / "results.csv")
        overrides_path = job / ".hydra" / "overrides.yaml"
        overrides = yaml.safe_load(overrides_path.read_text()) if overrides_path.is_file() else []
        values = {c: ", ".join(sorted(map(str, job_rows[c].dropna().unique()))) if c in job_rows else "–"
                  for c in ("code_version", "device", "hostname", "timing")}
        parts.append("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in (
            job.name, " ".join(overrides or []), values["code_version"], values["device"], values["hostname"],
            values["timing"], len(job_rows))) + "</tr>")
        config_path = job / ".hydra" / "config.yaml"
        if config_path.is_file():
            configs.append(f"<details><summary>{html.escape(job.name)}: configuration</summary>"
                           f"<pre>{html.escape(config_path.read_text())}</pre></details>")
    parts.append("</table>")
    return "\n".join(parts + configs)


def _realsense_priors(root: Path, stems: list[str]) -> dict[str, np.ndarray]:
    """The RealSense prior (m, on each capture's metric grid) of the captures, where the sweep's dataset can still
    be read here; an unreadable capture simply has no prior in its panel."""
    from bench.maroon import reader as maroon
    from methods.api import prior_image_m
    from methods.domain.errors import DatasetError

    jobs = _job_dirs(root)
    if not jobs:
        return {}
    dataset = _job_config(jobs[0]).get("dataset") or {}
    dataset_root = Path(str(dataset.get("root", "")))
    priors = {}
    for stem in stems:
        object_name, distance, _ = stem.rsplit("_", 2)
        try:
            capture = maroon.read_capture(dataset_root / object_name / distance, frame=int(dataset.get("frame", -1)),
                                          parts=("radar", "realsense"))
            priors[stem] = np.asarray(prior_image_m(capture, "realsense", capture.radar.grid))
        except (DatasetError, ValueError, OSError):
            continue
    return priors


def _pictures_section(root: Path, page_dir: Path) -> str:
    """Writes the pictures (bench.report.pictures) under `root/pictures/` (unchanged ones are kept) and links
    them, one block per capture."""
    from bench.report import pictures, tables

    runs = []
    for job in _job_dirs(root):
        if (job / "arrays.h5").is_file():
            runs.append((tables.job_label(job / "results.csv"), job / "arrays.h5"))
    if not runs:
        return "<p>No job wrote arrays.h5: no pictures.</p>"
    pictures.probe_renderer()         # its child process runs beside the reading of the priors
    stems = pictures.capture_stems([path for _, path in runs])
    written = pictures.sweep_pictures(runs, root / "pictures", _realsense_priors(root, stems))
    blocks = []
    for stem, files in written.items():
        ply_dir = html.escape(str(root / "pictures" / "point_clouds" / stem))
        blocks.append(f"<h4>{html.escape(stem)}</h4><p class='caption'>Point clouds (PLY files in {ply_dir}):</p>"
                      + _image(files["point_clouds"], f"{stem} point clouds", page_dir)
                      + "<p class='caption'>Depth, magnitude and signed error:</p>"
                      + _image(files["panel"], f"{stem} panel", page_dir))
    return "\n".join(blocks)


def _rows(root: Path) -> pd.DataFrame:
    from bench.report import merge

    return merge.merge(root) if not (root / "results.csv").is_file() else pd.read_csv(root / "results.csv")


def verdict_section(roots: list[Path], scored: dict[Path, Scored] | None = None) -> str:
    """The page's opening: per sweep root the verdict (bench.report.verdict) as lists."""
    from bench.report import tables, verdict

    parts = ["<h2 id='verdict'>Verdict</h2>"]
    for root in roots:
        root_scored = (scored or {}).get(root) or Scored.of(_rows(root))
        found = verdict.verdict(root_scored.summary, root_scored.pairs)
        name = table_name(root)
        parts.append(f"<h3>{html.escape(tables.TITLES.get(name, name))}</h3>")
        parts.append("<p>Best mean per metric (95 % bootstrap interval over captures; the margin over the runner-up "
                     "paired per capture):</p><ul>" + "".join(f"<li>{html.escape(t)}</li>" for t in found["best"])
                     + "</ul>")
        parts.append("".join(f"<p>{html.escape(t)}</p>" for t in found["front"]))
        if found["baseline"]:
            head, *lines = found["baseline"]
            parts.append(f"<p>{html.escape(head)}</p><ul>" + "".join(f"<li>{html.escape(t)}</li>" for t in lines)
                         + "</ul>")
        head, *lines = found["marked"]
        parts.append(f"<p>{html.escape(head)}</p>" + ("<ul>" + "".join(f"<li>{html.escape(t)}</li>" for t in lines)
                                                     + "</ul>" if lines else ""))
    return "\n".join(parts)


def root_section(root: Path, pictures: Future | None, page_dir: Path, scored: Scored | None = None
                 ) -> tuple[str, str]:
    """(table name, HTML section) of one sweep root; images linked relative to `page_dir`. `pictures`: the
    section of its pictures being drawn (`_pictures_section` in a thread of write_report), or None."""
    from bench.report import merge, tables

    scored = scored or Scored.of(_rows(root))
    rows, summary = scored.rows, scored.summary
    name = table_name(root)
    plot = merge.runtime_plot(root, name, summary)
    parts = [f"<h2 id='{html.escape(name)}'>{html.escape(tables.TITLES.get(name, name))} "
             f"<small>({html.escape(str(root))})</small></h2>",
             f"<p class='caption'>{html.escape(tables.caption(name, rows, summary=summary))}</p>",
             "<h3>Means over captures</h3>", _means_table(summary),
             "<h3>Spread across captures</h3><p class='caption'>Median and interquartile range [25 %, 75 %] of "
             "each metric (cm) over the captures of the means.</p>",
             _html_table(spread(rows, scored)),
             "<h3>Per object: P (cm)</h3>", _html_table(per_object(rows, scored=scored)),
             "<h3>Runtime against error</h3>", _image(plot, f"{name} runtime against error", page_dir)]
    if pictures is not None:
        parts += ["<h3>Pictures per capture</h3>", pictures.result()]
    parts += ["<h3>Cells: configuration and code version</h3>", _cells_section(root, rows)]
    return name, "\n".join(parts)


def write_report(roots: list[Path], out: Path, pictures: bool | list[Path] = True) -> Path:
    """The HTML page of the sweep roots at `out` (written atomically, and only when its text changed); returns
    `out`. `pictures`: for every root (True), none (False) or the roots listed."""
    chosen = [Path(p).resolve() for p in pictures] if isinstance(pictures, list) else None
    drawn = [root for root in roots if (bool(pictures) if chosen is None else root.resolve() in chosen)]
    page_dir = out.parent.resolve()
    # The pictures (drawn by worker processes, bench.report.pictures) are started first, in a thread that mostly
    # waits for them, so that the tables are scored meanwhile rather than before.
    with ThreadPoolExecutor(1) as drawing:
        sections_of_pictures = {root: drawing.submit(_pictures_section, root, page_dir) for root in drawn}
        scored = {root: Scored.of(_rows(root)) for root in roots}
        sections = [root_section(root, sections_of_pictures.get(root), page_dir, scored[root]) for root in roots]
    nav = " ".join(f"<a href='#{html.escape(name)}'>{html.escape(name)}</a>" for name, _ in sections)
    page = (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'><title>mm2fsk-bench report</title>"
            f"<style>{_STYLE}</style></head><body><h1>mm2fsk-bench report</h1>"
            f"<p class='caption'>From {html.escape(', '.join(map(str, roots)))}; images are the files beside it."
            f"</p><nav><a href='#verdict'>verdict</a> {nav}</nav>" + verdict_section(roots, scored)
            + "\n".join(body for _, body in sections) + f"{_LOADED_CHECK}</body></html>\n")
    if out.is_file() and out.read_text(encoding="utf-8") == page:
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(page, encoding="utf-8")
    os.replace(tmp, out)
    return out


def default_output(roots: list[Path]) -> Path:
    if len(roots) == 1:
        return roots[0] / "report.html"
    return Path(os.path.commonpath([r.resolve() for r in roots])) / "report.html"


def main() -> int:
    parser = cli.ArgumentParser(prog="python -m bench.report", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("roots", type=Path, nargs="+", metavar="SWEEP_ROOT",
                        help="sweep root(s) of `python -m bench -m ...` (holding <job>/results.csv)")
    parser.add_argument("--out", type=Path, help="the HTML file (default: see above)")
    parser.add_argument("--no-pictures", action="store_true", help="leave out the per-capture pictures (faster)")
    args = parser.parse_args()
    roots = [cli.existing_path(root, "dir", "sweep root") for root in args.roots]
    for root in roots:
        if not _job_dirs(root) and not (root / "results.csv").is_file():
            raise cli.UserError(root, "not a sweep root: no results.csv and no <job>/results.csv")
    out = cli.output_file(args.out or default_output(roots))
    print(write_report(roots, out, pictures=not args.no_pictures))
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
