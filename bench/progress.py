"""Progress bars for long commands (tqdm): drawn on stderr only when it is a terminal, so logs, pipes, CI and
SLURM job files get the plain progress lines instead."""
from __future__ import annotations

import sys

from tqdm import tqdm


def bar(total: int, description: str, unit: str = "step") -> tqdm:
    """A tqdm bar on stderr, disabled when stderr is not a terminal (`disable=None` is tqdm's own rule for that)."""
    return tqdm(total=total, desc=description, unit=unit, disable=None, file=sys.stderr, leave=False,
                dynamic_ncols=True)


def on_terminal() -> bool:
    """Whether bars are drawn (stderr is a terminal): then per-item lines go through `tqdm.write` above the bar."""
    return sys.stderr.isatty()
