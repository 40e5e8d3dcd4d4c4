"""A row's identity beyond method, frequencies, prior and grid: the `params` string of the settings a job changed.

`params` is canonical `key=value` pairs, sorted by key, space-separated, empty for a job that changed nothing
(the defaults of its method, prior, cell and experiment). It holds every command-line or sweep override that can
change a result: a method's parameters (`method.params.offset_mm=2` -> `offset_mm=2`), `threshold_db`,
`prior.fill`, `prior.max_jump_mm`, `roi=...`, `profile=...`, `freq.f_ghz=...`. Left out are the settings that
are columns of their own (method, freq, prior, grid, device, metrics), those that choose the data or where
results go (dataset, synth, store, report, hydra), how runtimes are taken (timing) and where rows are scored
(evaluation); cell and experiment pick the columns' values. The result store's key holds the values of every
setting already (bench.harness.app `_cell`); `params` is what a reader sees: results.csv's column, job lines
(`custom_d10_realsense offset_mm=2`) and the tables' row labels.
"""
from __future__ import annotations

import json

from hydra.core.override_parser.overrides_parser import OverridesParser

COLUMN_GROUPS = ("method", "freq", "prior", "grid", "cell", "experiment", "dataset", "synth")  # `group=option`
NOT_PARAMS = ("dataset", "synth", "store", "report", "hydra", "timing", "evaluation", "device", "metrics.faithful",
              "method._target_", "method.name", "freq.name", "prior.name", "grid.name")
#: what tells two results rows apart: the capture frame, the columns of its configuration, and `params`
ROW_IDENTITY = ("object", "distance", "frame", "method", "freq", "prior", "grid", "params", "device", "metrics")
_SHORT = "method.params."


def _value(value) -> str:
    """One text per value: 2 and 2.0 -> '2', True -> 'true', None -> 'null', lists and dicts as compact JSON."""
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    if isinstance(value, (list, dict, tuple)):
        return json.dumps(value, separators=(",", ":"), sort_keys=True)
    return str(value)


def _is_param(key: str) -> bool:
    if "." not in key and "/" not in key and key in COLUMN_GROUPS:
        return False
    return not any(key == name or key.startswith((f"{name}.", f"{name}/")) for name in NOT_PARAMS)


def params_string(task_overrides: list[str]) -> str:
    """The canonical `params` of a job from its overrides (HydraConfig `overrides.task`); later overrides of a
    key win, as in Hydra."""
    pairs = {}
    for override in OverridesParser.create().parse_overrides(list(task_overrides)):
        key = override.get_key_element().lstrip("+~")
        if not _is_param(key):
            continue
        name = key.removeprefix(_SHORT)
        pairs[name] = "deleted" if override.is_delete() else _value(override.value())
    return " ".join(f"{key}={pairs[key]}" for key in sorted(pairs))
