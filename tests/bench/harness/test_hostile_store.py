"""Never stale: a dataset file changed in place with the same size and modification time (the issue's case: the
store cached digests by path, size and mtime) is hashed again and its cells are computed again; a change within
the clock tick of the hashing (racy) is never cached; `verify=True` hashes every time."""
from __future__ import annotations

import os
import time
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from bench.harness.app import CONFIG_DIR, run
from bench.harness.store import RACY_S, Store

from hostile_tools import copy_capture, frame_file


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


def _rewrite_in_place(path: Path) -> None:
    """Change one byte of `path` without changing its size, inode or modification time (what `cp -p`, `touch -r`
    or an editor that restores times leave behind)."""
    info = os.stat(path)
    with open(path, "r+b") as handle:
        handle.seek(info.st_size - 1)
        last = handle.read(1)
        handle.seek(info.st_size - 1)
        handle.write(bytes([last[0] ^ 0x01]))
    os.utime(path, ns=(info.st_atime_ns, info.st_mtime_ns))
    after = os.stat(path)
    assert (after.st_size, after.st_mtime_ns, after.st_ino) == (info.st_size, info.st_mtime_ns, info.st_ino)


def test_a_settled_file_changed_in_place_gets_a_new_digest(tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(os.urandom(4096))
    time.sleep(RACY_S + 0.1)                           # settled: its digest is cached
    store = Store(tmp_path / "store")
    first = store.file_digest(path)
    assert len(list((tmp_path / "store" / "digests").iterdir())) == 1 and store.file_digest(path) == first
    _rewrite_in_place(path)
    assert store.file_digest(path) != first


def test_a_racy_file_is_hashed_but_not_cached(tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(os.urandom(4096))
    store = Store(tmp_path / "store")
    first = store.file_digest(path)                    # written just now: not cached
    assert not (tmp_path / "store" / "digests").exists()
    _rewrite_in_place(path)                            # possibly within the same ctime tick
    assert store.file_digest(path) != first


def test_verify_hashes_every_time(tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(os.urandom(4096))
    time.sleep(RACY_S + 0.1)
    store = Store(tmp_path / "store", verify=True)
    first = store.file_digest(path)
    _rewrite_in_place(path)
    assert store.file_digest(path) != first and not (tmp_path / "store" / "digests").exists()


def test_a_frame_changed_in_place_is_never_served_from_the_store(source_capture, tmp_path):
    root = tmp_path / "root"
    capture = copy_capture(source_capture, root)
    time.sleep(RACY_S + 0.1)                           # so that the first run caches every digest
    overrides = ["dataset=maroon", f"dataset.root={root}", "method=mm2fsk", "freq=d05", "prior=realsense",
                 f"store.dir={tmp_path / 'store'}"]
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=overrides)
        first = pd.DataFrame(run(cfg, tmp_path / "a"))
        assert any((tmp_path / "store" / "digests").iterdir())
        again = pd.DataFrame(run(cfg, tmp_path / "b"))
        _rewrite_in_place(frame_file(capture))
        changed = pd.DataFrame(run(cfg, tmp_path / "c"))
    assert not first.cached.any() and again.cached.all() and again.key.tolist() == first.key.tolist()
    assert not changed.cached.any() and changed.key.tolist() != first.key.tolist()
