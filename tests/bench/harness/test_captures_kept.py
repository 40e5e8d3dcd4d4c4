"""The process's caches of capture frames and ground truths (bench.harness.captures.Kept): bounded by the bytes of
the arrays they hold, not by a count, so that a sweep over many captures reads each one once."""
from __future__ import annotations

import numpy as np

from bench.harness import captures
from bench.maroon import reader

MIB = 2**20


def _array_mib(mib: float) -> np.ndarray:
    return np.zeros(int(mib * MIB) // 8)


def test_held_bytes_counts_each_array_once_through_dataclasses_and_containers(synth_root):
    capture = reader.read_capture(synth_root / "01_plate" / "30", frame=-1, parts=("radar",))
    radar = capture.radar.signal
    assert captures.held_bytes(capture) >= radar.nbytes
    assert captures.held_bytes((capture, [radar], {"again": radar})) == captures.held_bytes(capture)
    assert captures.held_bytes({"a": _array_mib(1), "b": (_array_mib(2), "text", 3)}) == 3 * MIB


def test_kept_drops_the_least_recently_used_beyond_its_bytes():
    kept = captures.Kept(limit_mib=3)
    for key in "abcd":
        kept.put(key, _array_mib(1))
    assert [key for key in "abcd" if key in kept] == ["b", "c", "d"]
    assert kept.get("b") is not None             # now the most recently used: "c" goes next
    kept.put("e", _array_mib(1))
    assert [key for key in "bcde" if key in kept] == ["b", "d", "e"]
    kept.put("big", _array_mib(10))              # the newest stays whatever its size, alone
    assert len(kept) == 1 and "big" in kept
    assert kept.pop("big") is not None and kept.pop("big", "none") == "none"


def test_a_sweep_over_more_captures_than_the_old_count_reads_each_once(synth_root, monkeypatch):
    """40 capture folders read by two cells, one after the other: each read from disk once (a cache of 16 entries,
    as before, read all 80 times: the second cell found none of the first cell's captures)."""
    monkeypatch.setattr(captures, "_CAPTURES", captures.Kept())
    template = reader.read_capture(synth_root / "01_plate" / "30", frame=-1, parts=("radar",))
    reads = []

    def read_capture(capture_dir, **_):
        reads.append(capture_dir)
        return template

    monkeypatch.setattr(reader, "read_capture", read_capture)
    folders = [synth_root / f"object_{i:02d}" / "30" for i in range(40)]
    for _cell in range(2):
        for folder in folders:
            captures.read(folder, -1, ("radar",), False, (None, None))
    assert len(reads) == 40 and set(reads) == set(folders)
    assert 40 * template.radar.signal.nbytes < captures.KEPT_MIB * MIB      # what the test relies on
