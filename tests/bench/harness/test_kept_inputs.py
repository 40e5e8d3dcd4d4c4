"""A sweep without a result store (`store.dir=null`) keeps the ground truths' rasters and the parsed meshes by
content in `store.cache` (bench.harness.app._kept_inputs, bench.harness.captures): a later process casts no ray and
parses no mesh, and scores the same; a kept file is never trusted: one that is corrupt, written for another key or
linking elsewhere is ignored with a warning naming it, and cast or parsed anew."""
from __future__ import annotations

import logging

import h5py
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from bench import cli
from bench.harness import CONFIG_DIR, app, captures
from bench.maroon import reader

SCORES = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm", "off_pct", "off_err_cm", "coverage_pct", "C_g_px", "C_s_px", "P_px",
          "P_e_px", "valid_px", "failure")


def _cfg(synth_root, cache, *overrides):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=["dataset=maroon", f"dataset.root={synth_root}",
                                                      "dataset.captures=[01_plate/30]", "store.dir=null",
                                                      f"store.cache={cache}", "method=mm2fsk", "freq=d05",
                                                      "prior=photogrammetry", *overrides])


@pytest.fixture
def counted(monkeypatch):
    """Ray casts and mesh parses counted; `fresh()` empties the process's memory (a new process)."""
    casts, parses = [], []
    real_cast, real_parse = captures.ground_truth_rasters_m, reader.read_mesh
    monkeypatch.setattr(captures, "ground_truth_rasters_m", lambda c, g: casts.append(c.name) or real_cast(c, g))
    monkeypatch.setattr(reader, "read_mesh", lambda path: parses.append(path) or real_parse(path))

    def fresh():
        monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
        monkeypatch.setattr(captures, "_GROUND_TRUTHS", type(captures._GROUND_TRUTHS)())
        app._store.cache_clear()                                                     # digests not in memory

    return casts, parses, fresh


def _same_scores(a: dict, b: dict) -> None:
    for column in SCORES:
        assert a[column] == b[column] or (np.isnan(a[column]) and np.isnan(b[column])), column


def test_a_second_process_reads_the_kept_ground_truth_and_mesh_and_scores_the_same(synth_root, tmp_path, counted):
    casts, parses, fresh = counted
    fresh()
    (plain,) = app.run(_cfg(synth_root, "null"), tmp_path / "plain")            # nothing kept
    assert (len(casts), len(parses)) == (1, 1)
    fresh()
    (first,) = app.run(_cfg(synth_root, tmp_path / "cache"), tmp_path / "first")
    assert (len(casts), len(parses)) == (2, 2)
    assert len(list((tmp_path / "cache" / "ground_truth").glob("*.h5"))) == 1
    assert len(list((tmp_path / "cache" / "meshes").glob("*.h5"))) == 1
    fresh()
    (kept,) = app.run(_cfg(synth_root, tmp_path / "cache"), tmp_path / "kept")
    assert (len(casts), len(parses)) == (2, 2)                                     # no cast, no parse
    _same_scores(plain, first)
    _same_scores(plain, kept)
    assert not list(synth_root.rglob("*.h5"))                                       # nothing in the dataset


def _corrupt(path):
    path.write_bytes(b"not HDF5" * 100)


def _foreign(path):
    other = path.with_name("other.h5")
    with h5py.File(other, "w") as h5, h5py.File(path, "r") as mine:
        for name in mine:
            h5.create_dataset(name, data=mine[name][()])
        h5.attrs["key"] = "0" * 64                                                 # another capture's file
    other.replace(path)


def _linked(path):
    target = path.with_name("elsewhere.h5")
    path.replace(target)
    with h5py.File(path, "w") as h5, h5py.File(target, "r") as real:
        for name in real:
            h5[name] = h5py.ExternalLink(str(target), name)
        h5.attrs["key"] = real.attrs["key"]


def _wrong_shape(path):
    with h5py.File(path, "r+") as h5:
        for name in list(h5):
            values = h5[name][()]
            del h5[name]
            h5.create_dataset(name, data=values[:-1])


@pytest.mark.parametrize("damage, reason", [(_corrupt, "unreadable HDF5"), (_foreign, "written for another key"),
                                            (_linked, "ExternalLink"), (_wrong_shape, "must be")])
def test_a_bad_kept_file_is_ignored_with_a_warning_and_made_anew(synth_root, tmp_path, counted, caplog, damage,
                                                                 reason):
    casts, parses, fresh = counted
    cache = tmp_path / "cache"
    fresh()
    (first,) = app.run(_cfg(synth_root, cache), tmp_path / "first")
    (raster,) = (cache / "ground_truth").glob("*.h5")
    (mesh,) = (cache / "meshes").glob("*.h5")
    damage(raster)
    damage(mesh)
    fresh()
    with caplog.at_level(logging.WARNING, logger="bench"):
        (again,) = app.run(_cfg(synth_root, cache), tmp_path / "again")
    warned = [r.getMessage() for r in caplog.records if "is not usable" in r.getMessage()]
    assert len(warned) == 2 and all(reason in line for line in warned), warned
    assert any(str(raster) in line for line in warned) and any(str(mesh) in line for line in warned)
    assert (len(casts), len(parses)) == (2, 2)                                     # cast and parsed anew
    _same_scores(first, again)
    fresh()
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="bench"):
        (third,) = app.run(_cfg(synth_root, cache), tmp_path / "third")            # the files were made anew
    assert (len(casts), len(parses)) == (2, 2) and not caplog.records
    _same_scores(first, third)


def test_a_cache_inside_the_dataset_is_refused(synth_root, tmp_path, counted, monkeypatch):
    with pytest.raises(cli.UserError, match="inside the dataset"):
        app.run(_cfg(synth_root, synth_root / "01_plate" / "cache"), tmp_path / "run")
    assert not (synth_root / "01_plate" / "cache").exists()
    casts, _, fresh = counted
    monkeypatch.setenv("XDG_CACHE_HOME", str(synth_root / "xdg"))                 # auto: nothing kept, no error
    fresh()
    app.run(_cfg(synth_root, "auto"), tmp_path / "auto")
    assert len(casts) == 1 and not (synth_root / "xdg").exists()


def test_auto_keeps_in_the_users_cache_folder_and_an_unwritable_one_keeps_nothing(synth_root, tmp_path, counted,
                                                                                   monkeypatch):
    casts, _, fresh = counted
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    fresh()
    app.run(_cfg(synth_root, "auto"), tmp_path / "a")
    assert len(list((tmp_path / "xdg" / "mm2fsk-bench" / "ground_truth").glob("*.h5"))) == 1
    (tmp_path / "ro").mkdir(mode=0o500)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "ro"))
    monkeypatch.setattr(app.os, "access", lambda path, mode: False)               # root may write anywhere
    fresh()
    app.run(_cfg(synth_root, "auto"), tmp_path / "b")
    assert len(casts) == 2 and not list((tmp_path / "ro").iterdir())


def test_a_kept_ground_truth_is_the_one_derived_from_the_mesh_array_for_array(synth_root, tmp_path, counted):
    from metrics.evaluate import ground_truth_arrays

    _, _, fresh = counted
    gts = []
    for name in ("cast", "kept"):
        fresh()
        app.run(_cfg(synth_root, tmp_path / "cache"), tmp_path / name)
        (gt,) = captures._GROUND_TRUTHS.values()
        gts.append(gt)
    cast, kept = (ground_truth_arrays(gt) for gt in gts)
    assert cast.keys() == kept.keys() and len(cast) == 7
    for name, values in cast.items():
        assert kept[name].dtype == values.dtype and kept[name].flags.c_contiguous, name
        np.testing.assert_array_equal(kept[name], values, err_msg=name)
    assert (gts[1].mask_bb_m, gts[1].reference.mask_bb_m, gts[1].mask_erosion) == \
        (gts[0].mask_bb_m, gts[0].reference.mask_bb_m, gts[0].mask_erosion)


def test_another_code_version_parses_the_mesh_again(synth_root, tmp_path, counted, monkeypatch):
    """A kept mesh is the reader's output: a new code version (a changed reader) parses the OBJ again."""
    casts, parses, fresh = counted
    fresh()
    app.run(_cfg(synth_root, tmp_path / "cache"), tmp_path / "first")
    monkeypatch.setattr(captures, "code_version", lambda: "another-version")
    fresh()
    app.run(_cfg(synth_root, tmp_path / "cache"), tmp_path / "second")
    assert len(parses) == 2 and len(list((tmp_path / "cache" / "meshes").glob("*.h5"))) == 2


def test_kept_files_that_cannot_be_written_leave_the_run_going(synth_root, tmp_path, counted, monkeypatch, caplog):
    """A full disk or quota while keeping: one warning per file, the row scored as without a cache."""
    casts, parses, fresh = counted
    fresh()
    (plain,) = app.run(_cfg(synth_root, "null"), tmp_path / "plain")

    write = captures.atomic.write_bytes

    def full(path, data):                                 # the cache's file system is full, the outputs' is not
        if tmp_path / "cache" in path.parents:
            raise OSError(122, "Disk quota exceeded", str(path))
        return write(path, data)

    monkeypatch.setattr(captures.atomic, "write_bytes", full)
    fresh()
    with caplog.at_level(logging.WARNING, logger="bench"):
        (row,) = app.run(_cfg(synth_root, tmp_path / "cache"), tmp_path / "full")
    _same_scores(plain, row)
    assert sum("could not keep" in r.getMessage() and "quota" in r.getMessage() for r in caplog.records) == 2
