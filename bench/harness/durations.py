"""How long a configuration took per capture frame in earlier runs: the estimate progress lines give before a
job's first frame is done (`<store>/durations.json`, beside the result store's cells).

Keyed by the cell's configuration without the code version (an estimate survives a code change) and the
machine's name; the value is the mean wall seconds of a computed frame (reading, method, metrics, outputs).
Written atomically; two jobs finishing at once may drop one's update, which only costs an estimate.
"""
from __future__ import annotations

import hashlib
import json
import socket
from pathlib import Path

from bench.harness import atomic


def configuration_id(cell: dict) -> str:
    """The id of a cell's configuration (bench.harness.app `_cell`) on this machine, code version left out."""
    described = {key: value for key, value in cell.items() if key != "code"}
    text = json.dumps({"cell": described, "host": socket.gethostname()}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


class Durations:
    """Seconds per computed frame by configuration id, in `<root>/durations.json`."""

    def __init__(self, root: Path):
        self.path = Path(root) / "durations.json"

    def _read(self) -> dict:
        try:
            return json.loads(self.path.read_text())
        except (OSError, ValueError):      # none yet, or unreadable: no estimate
            return {}

    def seconds(self, configuration: str) -> float | None:
        value = self._read().get(configuration)
        return float(value) if isinstance(value, (int, float)) else None

    def record(self, configuration: str, seconds_per_frame: float) -> None:
        known = self._read()
        known[configuration] = seconds_per_frame
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_bytes(self.path, json.dumps(known).encode())
