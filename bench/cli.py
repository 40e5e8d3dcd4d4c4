"""Shared command-line behaviour: dataset problems end in one clear line and a non-zero exit, not a traceback."""
from __future__ import annotations

import sys
from collections.abc import Callable

from bench.errors import DatasetError

EXIT_DATASET_ERROR = 2


def run_guarded(main: Callable[[], int | None]) -> None:
    """Run `main`; on a DatasetError print `error: <file>: <problem>` to stderr and exit 2."""
    try:
        code = main()
    except DatasetError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(EXIT_DATASET_ERROR)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(code or 0)
