"""The in-process launcher (hydra_plugins/mm2fsk_bench/inprocess.py): Hydra's basic launcher's jobs, folders,
files and job state with its per-job set-up cut, the default of `python -m bench -m`."""
from __future__ import annotations

import copy
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra._internal.callbacks import Callbacks
from hydra.core.hydra_config import HydraConfig
from hydra.core.utils import JobStatus, run_job
from hydra.types import HydraContext, RunMode
from omegaconf import OmegaConf, open_dict

from bench.harness import CONFIG_DIR, app
from bench.harness.results import MEASURED_COLUMNS
from bench.harness.sizing import timing_mode
from hydra_plugins.mm2fsk_bench import inprocess

INPROCESS = "hydra_plugins.mm2fsk_bench.inprocess.InProcessLauncher"


def _job_config(sweep_dir: Path, *overrides: str):
    """A sweep job's configuration as the launcher gets it: composed, job number set, no output folder yet."""
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", return_hydra_config=True,
                      overrides=["hydra/job_logging=disabled", "hydra/hydra_logging=disabled",
                                 f"hydra.sweep.dir={sweep_dir}", "cell=2fsk_d05", *overrides])
    with open_dict(cfg):
        cfg.hydra.job.id = cfg.hydra.job.num = 3
        cfg.hydra.mode = RunMode.MULTIRUN
        cfg.hydra.job.name = "app"
    return cfg


def _task(seen: list, fail: bool = False):
    def task(cfg):
        hydra_cfg = HydraConfig.get()
        seen.append({"yaml": OmegaConf.to_yaml(cfg), "struct": OmegaConf.is_struct(cfg),
                     "readonly": OmegaConf.is_readonly(cfg), "has_hydra": "hydra" in cfg,
                     "output_dir": hydra_cfg.runtime.output_dir, "num": hydra_cfg.job.num, "cwd": os.getcwd(),
                     "env": os.environ.get("L7_TEST_ENV"), "subdir": hydra_cfg.sweep.subdir,
                     "hydra_yaml": OmegaConf.to_yaml(HydraConfig.instance().cfg)})
        if fail:
            raise ValueError("this job fails")
        return "done"
    return task


def _files(folder: Path, sweep_dir: Path) -> dict[str, str]:
    return {p.name: p.read_text().replace(str(sweep_dir), "SWEEP") for p in sorted((folder / ".hydra").iterdir())}


@pytest.mark.parametrize("chdir, fail", [(False, False), (True, False), (False, True)],
                         ids=["plain", "chdir", "failing job"])
def test_a_job_sees_and_leaves_what_hydras_run_job_gives_it(tmp_path, monkeypatch, chdir, fail):
    """The job's configuration, flags, Hydra state, working folder, environment, its .hydra files (bytes) and its
    return value as hydra.core.utils.run_job gives them, with one `set_config` where Hydra makes two."""
    overrides = [f"hydra.job.chdir={str(chdir).lower()}", "+hydra.job.env_set.L7_TEST_ENV=set"]
    results, cwd, set_configs = {}, os.getcwd(), []
    real_set = HydraConfig.set_config
    monkeypatch.setattr(HydraConfig, "set_config", lambda self, c: set_configs.append(1) or real_set(self, c))
    for name in ("hydra", "here"):
        sweep_dir = tmp_path / name
        cfg = _job_config(sweep_dir, *overrides)
        context = HydraContext(config_loader=None, callbacks=Callbacks(cfg))
        seen = []
        set_configs.clear()
        if name == "hydra":
            ret = run_job(task_function=_task(seen, fail), config=cfg, job_dir_key="hydra.sweep.dir",
                          job_subdir_key="hydra.sweep.subdir", hydra_context=context)
        else:
            with ThreadPoolExecutor(1) as writer:
                written = []
                ret = inprocess.run_job_here(context, _task(seen, fail), cfg, writer, written)
            [future.result() for future in written]
        assert os.getcwd() == cwd and "L7_TEST_ENV" not in os.environ            # restored after the job
        folder = Path(seen[0]["output_dir"])
        results[name] = {
            "seen": {k: str(v).replace(str(sweep_dir), "SWEEP") for k, v in seen[0].items()},
            "files": _files(folder, sweep_dir), "set_config": len(set_configs), "status": ret.status,
            "return": repr(ret._return_value), "cfg": OmegaConf.to_yaml(ret.cfg),
            "hydra_cfg": OmegaConf.to_yaml(ret.hydra_cfg).replace(str(sweep_dir), "SWEEP"),
            "overrides": ret.overrides, "working_dir": str(ret.working_dir).replace(str(sweep_dir), "SWEEP"),
            "flags": (OmegaConf.is_struct(ret.cfg), OmegaConf.is_readonly(ret.cfg))}
    hydra, here = results["hydra"], results["here"]
    assert (hydra.pop("set_config"), here.pop("set_config")) == (2, 1)
    assert here == hydra
    assert here["seen"]["cwd"] == (here["seen"]["output_dir"] if chdir else cwd)
    assert here["status"] == (JobStatus.FAILED if fail else JobStatus.COMPLETED)
    assert set(here["files"]) == {"config.yaml", "hydra.yaml", "overrides.yaml"}


def test_the_job_config_is_a_copy_without_the_hydra_node(tmp_path):
    cfg = _job_config(tmp_path)
    task = inprocess._task_config(cfg)
    assert "hydra" in cfg and "hydra" not in task and OmegaConf.is_struct(task)
    reference = copy.deepcopy(cfg)
    with open_dict(reference):
        del reference["hydra"]
    assert OmegaConf.to_yaml(task) == OmegaConf.to_yaml(reference)
    with open_dict(task):
        task.method.name = "changed"                                    # a copy: the job's edits stay its own
    assert cfg.method.name == "2fsk"


class _Loader:
    def __init__(self, cfg):
        self.cfg = cfg

    def load_sweep_config(self, master_config, overrides):
        return copy.deepcopy(self.cfg)


def test_the_launch_returns_after_the_files_are_written_and_a_failed_write_fails_it(tmp_path, monkeypatch):
    cfg = _job_config(tmp_path / "sweep")
    launcher = inprocess.InProcessLauncher()
    launcher.setup(hydra_context=HydraContext(config_loader=_Loader(cfg), callbacks=Callbacks(cfg)),
                   task_function=lambda c: None, config=cfg)
    real_write, writers = inprocess._write_files, []

    def slow_write(folder, containers):
        writers.append(threading.current_thread() is not threading.main_thread())
        time.sleep(0.3)
        real_write(folder, containers)

    monkeypatch.setattr(inprocess, "_write_files", slow_write)
    runs = launcher.launch([["cell=2fsk_d05"], ["cell=2fsk_d1"]], initial_job_idx=0)
    assert [run.hydra_cfg.hydra.job.num for run in runs] == [0, 1] and writers == [True, True]
    for run in runs:                                                    # written off the main thread, waited for
        assert (Path(run.hydra_cfg.hydra.runtime.output_dir) / ".hydra" / "overrides.yaml").is_file()

    def failed_write(folder, containers):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(inprocess, "_write_files", failed_write)
    with pytest.raises(OSError, match="No space left"):
        launcher.launch([["cell=2fsk_d05"]], initial_job_idx=0)


def test_inprocess_is_the_default_launcher_its_jobs_timed_alone_and_their_outputs_deferred(monkeypatch):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", return_hydra_config=True)
    assert cfg.hydra.launcher._target_ == INPROCESS
    monkeypatch.setenv("BENCH_SWEEP_JOBS", "13")
    hydra_cfg = OmegaConf.create({"mode": RunMode.MULTIRUN, "launcher": {"_target_": INPROCESS}})
    assert timing_mode(hydra_cfg) == "alone" and app._next_job_here(hydra_cfg)


def _bench_sweep(tmp_path, synth_root, launcher: str):
    root = tmp_path / launcher
    result = subprocess.run([sys.executable, "-m", "bench", "-m", "experiment=table2",
                             "hydra.sweeper.params.freq='d8,d10'", f"hydra/launcher={launcher}", "dataset=maroon",
                             f"dataset.root={synth_root}", "dataset.captures=[01_plate/30]", "store.dir=null",
                             f"store.cache={tmp_path / 'cache'}", f"hydra.sweep.dir={root}"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return root, result.stdout


def test_a_sweep_gives_the_basic_launchers_rows_files_and_lines(synth_root, tmp_path):
    rows, files, lines = {}, {}, {}
    for launcher in ("basic", "inprocess"):
        root, stdout = _bench_sweep(tmp_path, synth_root, launcher)
        merged = pd.read_csv(root / "results.csv")
        assert set(merged.timing) <= {"alone", "contended"}                # one job at a time
        rows[launcher] = merged.drop(columns=[*MEASURED_COLUMNS, "hostname",
                                              *(c for c in merged if c.startswith("t_"))])   # stage times
        files[launcher] = {str(p.relative_to(root)): p.read_bytes().replace(str(root).encode(), b"ROOT")
                           for p in sorted(root.glob("*/.hydra/*.yaml")) if p.name != "hydra.yaml"}
        files[launcher].update({str(p.relative_to(root)): p.read_bytes() for p in sorted(root.glob("*/depth/*"))})
        lines[launcher] = [line.split(": 1 capture")[0] for line in stdout.splitlines() if line.startswith("[table")]
    pd.testing.assert_frame_equal(rows["inprocess"], rows["basic"])
    assert files["inprocess"] == files["basic"] and len(files["basic"]) >= 4
    assert lines["inprocess"] == lines["basic"] == ["[table2 1/2] mm2fsk_d8_photogrammetry",
                                                    "[table2 2/2] mm2fsk_d10_photogrammetry"]


@pytest.mark.parametrize("sweep", [["experiment=table2"], ["experiment=table3"], ["experiment=beyond"],
                                   ["cell=mm2fsk_d10", "device=cpu,cuda", "threshold_db=-10,-20"]])
def test_a_sweeps_kept_compositions_equal_fresh_ones(sweep):
    """Every job's configuration as the sweeper keeps it for the launcher (sweeper._ComposedOnce, composed up front)
    equals its composition from scratch, value overrides included: one job's values never reach another's (config
    files shared between compositions once gave a SLURM sweep's device=cpu job the device=cuda job's memory)."""
    from hydra._internal.hydra import Hydra
    from hydra._internal.utils import create_config_search_path
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from hydra_plugins.mm2fsk_bench import sweeper

    try:                        # Hydra's global state, as `python -m bench` sets it up: cleared for the next tests
        loader = Hydra.create_main_hydra2(task_name="app", config_search_path=create_config_search_path(
            str(CONFIG_DIR))).config_loader
        master = loader.load_configuration("config", [*sweep, "dataset=maroon", "dataset.root=/x"], RunMode.MULTIRUN)
        swept = [*(master.hydra.sweeper.params or {}).items(), *((o.get_key_element(), o.value()) for o in
                 OverridesParser.create().parse_overrides(sweep) if o.is_sweep_override())]
        batch = [[]]
        for key, values in swept:
            values = values.split(",") if isinstance(values, str) else [str(v) for v in values.list]
            batch = [[*job, f"{key}={value}"] for job in batch for value in values]
        once = sweeper._ComposedOnce(loader)
        for job in batch:
            once.keep(master, job)
        kept = [OmegaConf.to_yaml(once.load_sweep_config(master, job)) for job in batch]
        fresh = [OmegaConf.to_yaml(loader.load_sweep_config(master, job)) for job in batch]
    finally:
        GlobalHydra.instance().clear()
    assert kept == fresh and len(batch) >= 4 and len(set(kept)) == len(batch)


@pytest.mark.parametrize("mode, launcher, isolated", [
    (RunMode.MULTIRUN, INPROCESS, False),
    (RunMode.MULTIRUN, "hydra._internal.core_plugins.basic_launcher.BasicLauncher", False),
    (RunMode.MULTIRUN, "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher", True),
    (RunMode.RUN, INPROCESS, False)])
def test_only_jobs_in_other_processes_get_a_warp_kernel_cache_of_their_own(monkeypatch, mode, launcher, isolated):
    """Jobs that may compile side by side get a cache folder per process (DESIGN.md 8); jobs run one after another
    in the sweep's process keep Warp's own cache, which the next sweep finds warm."""
    monkeypatch.delenv("WARP_CACHE_PATH", raising=False)
    hydra_cfg = OmegaConf.create({"mode": mode, "launcher": {"_target_": launcher}})
    monkeypatch.setattr(HydraConfig, "get", staticmethod(lambda: hydra_cfg))
    app._isolate_warp_cache()
    assert ("WARP_CACHE_PATH" in os.environ) == isolated
    if isolated:
        assert os.environ["WARP_CACHE_PATH"].endswith(f"-{os.getpid()}")
