"""Build synthetic captures: scene -> radar frames + depth frames + ground truth, written atomically and cached.

Cache: `<root>/synth_manifest.json` maps "object/distance" to the hash of generator version + config. A capture
whose directory exists and whose hash matches is skipped; any other is rebuilt in a hidden temporary folder beside
it and moved into place with a rename, so an interrupted run never leaves a half-written capture.

Concurrency (bench.synth.ownership): the generator writes only into a root it owns (manifest created first, a
root with other data is refused) and under the root's exclusive lock, so parallel jobs asking for the same captures
generate each capture once; temp folders left by a dead process are removed before a capture is rebuilt.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import threading
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from bench.synth import motion, ownership, workers
from bench.synth.config import DISTANCE_RANGE_CM, SynthConfig, capture_hash
from bench.synth.parts import CAPTURE_PARTS, build_part
from bench.synth.radar.leg_sum import single_threaded_blas
from bench.synth.scenes import CATALOGUE, FULL_CATALOGUE

MANIFEST_NAME = ownership.MANIFEST_NAME
# where the radar sums run: "cpu" NumPy (the default: the demo's data do not depend on the machine), "cuda" and
# "warp-cpu" Warp (bench.synth.radar.warp_sum; frames within docs/measurements/synth.md's tolerance of NumPy's)
RADAR_DEVICES = ("cpu", "cuda", "warp-cpu")
DEFAULT_DISTANCES_CM = (30, 40, 50)


@dataclass(frozen=True)
class CaptureResult:
    """What happened to one capture: status is 'generated' or 'cached'; seconds of wall time."""

    path: Path
    status: str
    seconds: float


class _Manifest:
    """`<root>/synth_manifest.json`; written only under the root's lock (ownership.exclusive)."""

    def __init__(self, root: Path):
        self.path = root / MANIFEST_NAME

    def read(self) -> dict:
        try:
            return json.loads(self.path.read_text()).get("captures", {})
        except (OSError, ValueError):
            return {}

    _lock = threading.Lock()        # captures built at once (generate_catalogue) record one after the other

    def record(self, key: str, entry: dict) -> None:
        with self._lock:
            self._record(key, entry)

    def _record(self, key: str, entry: dict) -> None:
        captures = self.read()
        captures[key] = entry
        tmp = self.path.with_name(f".{MANIFEST_NAME}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"captures": captures}, indent=2, sort_keys=True))
        os.replace(tmp, self.path)


def _remove_stale_temporaries(object_dir: Path, distance_cm: int) -> None:
    """Delete leftovers of interrupted runs (hidden temp/old folders); the caller holds the root's lock, so no live
    writer on any host owns one (ownership.is_leftover)."""
    for entry in object_dir.glob(f".{distance_cm}.*"):
        if ownership.is_leftover(entry):
            shutil.rmtree(entry, ignore_errors=True)


def _check(object_name: str, distance_cm: int, config: SynthConfig, device: str = "cpu") -> None:
    config.validate()
    if device not in RADAR_DEVICES:
        raise ValueError(f"device {device!r} is not one of {', '.join(RADAR_DEVICES)}")
    motion.validate(config)
    if object_name not in FULL_CATALOGUE:
        raise ValueError(f"unknown object {object_name!r}; known: {', '.join(FULL_CATALOGUE)}")
    if not DISTANCE_RANGE_CM[0] <= int(distance_cm) <= DISTANCE_RANGE_CM[1]:
        raise ValueError(f"distance {distance_cm} cm is outside {DISTANCE_RANGE_CM[0]}..{DISTANCE_RANGE_CM[1]} cm")


@dataclass(frozen=True)
class _Pending:
    """A capture to build: its manifest key and hash, its folder, the temp folder its parts are written into."""

    key: str
    digest: str
    target: Path
    tmp: Path
    start: float


def _prepare(root: Path, object_name: str, distance_cm: int, config: SynthConfig, force: bool,
             device: str) -> CaptureResult | _Pending:
    """The cached capture, or an empty temp folder to build it in; the caller has claimed `root` and holds its
    lock."""
    start = time.perf_counter()
    target = root / object_name / str(int(distance_cm))
    key, digest = f"{object_name}/{int(distance_cm)}", capture_hash(config, object_name, distance_cm, device)
    recorded = _Manifest(root).read().get(key, {})
    if not force and target.is_dir() and recorded.get("hash") == digest:
        return CaptureResult(target, "cached", time.perf_counter() - start)
    if target.exists():
        ownership.check_replaceable(target, recorded)
    target.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(target.parent, distance_cm)
    tmp = target.parent / f".{distance_cm}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    return _Pending(key, digest, target, tmp, start)


def _finish(root: Path, pending: _Pending, config: SynthConfig, device: str) -> CaptureResult:
    """Move the built temp folder into place (replacing an old capture) and record it in the manifest."""
    target, tmp = pending.target, pending.tmp
    if target.exists():
        old = tmp.with_name(tmp.name.replace(".tmp-", ".old-", 1))
        os.rename(target, old)
        os.rename(tmp, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(tmp, target)
    seconds = time.perf_counter() - pending.start
    _Manifest(root).record(pending.key, {"hash": pending.digest, "config": config.to_dict(), "device": device,
                                         "seconds": round(seconds, 3), "content": ownership.content_digest(target)})
    return CaptureResult(target, "generated", seconds)


def _ensure_locked(root: Path, object_name: str, distance_cm: int, config: SynthConfig,
                   force: bool, device: str = "cpu") -> CaptureResult:
    """ensure_capture's work, in this thread; the caller has claimed `root` and holds its lock."""
    plan = _prepare(root, object_name, distance_cm, config, force, device)
    if isinstance(plan, CaptureResult):
        return plan
    try:
        for part in CAPTURE_PARTS:
            build_part(plan.tmp, part, object_name, distance_cm, config, device)
        return _finish(root, plan, config, device)
    finally:
        shutil.rmtree(plan.tmp, ignore_errors=True)


DEFAULT_CONFIG = SynthConfig()     # frozen: one shared default instance


def ensure_capture(root, object_name: str, distance_cm: int, config: SynthConfig = DEFAULT_CONFIG,
                   force: bool = False, on_wait: Callable[[], None] | None = None,
                   device: str = "cpu") -> CaptureResult:
    """Generate one capture unless an up-to-date one (same hash in the manifest) already exists.

    `device` (RADAR_DEVICES) is where the radar sums run; it is part of the cache key unless "cpu" and recorded in
    the manifest. Raises ownership.ForeignRootError for a root with data the generator did not write.
    """
    _check(object_name, distance_cm, config, device)
    root = Path(root)
    ownership.claim(root)
    with ownership.exclusive(root, on_wait):
        return _ensure_locked(root, object_name, int(distance_cm), config, force, device)


def generate_capture(root, object_name: str, distance_cm: int, config: SynthConfig = DEFAULT_CONFIG,
                     force: bool = False, device: str = "cpu") -> Path:
    """Path of the capture `<root>/<object_name>/<distance_cm>`, generated if missing or stale."""
    return ensure_capture(root, object_name, distance_cm, config, force, device=device).path


def generate_catalogue(root, distances: Iterable[int] = DEFAULT_DISTANCES_CM, objects: Iterable[str] | None = None,
                       config: SynthConfig = DEFAULT_CONFIG, force: bool = False,
                       log: Callable[[CaptureResult], None] | None = None,
                       on_wait: Callable[[], None] | None = None, device: str = "cpu") -> list[CaptureResult]:
    """Ensure every (object, distance) capture; `objects=None` means the demo's catalogue (scenes.CATALOGUE);
    the radar sums on `device` (ensure_capture).

    Holds the root's lock throughout: a concurrent call waits (`on_wait()` is called once when it has to) and
    then finds the captures cached. Builds the captures' parts (parts.CAPTURE_PARTS), `workers.capture_workers()`
    at once, in worker processes or threads (bench.synth.workers; every part draws from its own seeded streams and
    sums in a fixed order, so the files do not depend on this); `log` sees the captures in order.
    Raises ownership.ForeignRootError for a root with other data.
    """
    pairs = [(o, int(d)) for o in (list(objects) if objects is not None else list(CATALOGUE)) for d in distances]
    for object_name, distance_cm in pairs:
        _check(object_name, distance_cm, config, device)
    root = Path(root)
    ownership.claim(root)
    unique = list(dict.fromkeys(pairs))       # a capture asked for twice is built once
    done: dict[tuple[str, int], CaptureResult] = {}
    # BLAS single-threaded throughout (in worker processes too): calls from captures built at once into a
    # multi-threaded OpenBLAS contend (its workers busy-wait); the captures' own threads use the cores
    with ownership.exclusive(root, on_wait), single_threaded_blas():
        plans: dict = {}
        pending: dict = {}
        try:
            for pair in unique:                   # inside the try: a later pair's error removes earlier temp folders
                plans[pair] = _prepare(root, *pair, config, force, device)
                if isinstance(plans[pair], _Pending):
                    pending[pair] = plans[pair]
            with (workers.builders(min(workers.capture_workers(), len(pending) * len(CAPTURE_PARTS)), device)
                  if pending else contextlib.nullcontext()) as submit:
                # every capture's radar part first (the longest), then the cameras, then the ground truths
                parts = {(pair, part): submit(build_part, plan.tmp, part, *pair, config, device)
                         for part in CAPTURE_PARTS for pair, plan in pending.items()}
                try:
                    for pair in unique:
                        if pair in pending:
                            for part in CAPTURE_PARTS:
                                parts[pair, part].result()
                            plans[pair] = _finish(root, pending.pop(pair), config, device)
                        done[pair] = plans[pair]
                        if log is not None:
                            log(done[pair])
                except BaseException:
                    for future in parts.values():
                        future.cancel()
                    raise
        finally:              # after the builders have stopped: nothing writes into these any more
            for plan in pending.values():
                shutil.rmtree(plan.tmp, ignore_errors=True)
    return [done[pair] for pair in pairs]

