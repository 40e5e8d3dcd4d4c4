"""bench.slurm: time limits from the cell, the shared-path check, a dead job's cause, temp-folder ownership by the
lock; and, opt-in, the whole SLURM path on a real single-node cluster (scripts/slurm_try.sh)."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest
from omegaconf import OmegaConf

from bench import cli, slurm

REPO = Path(__file__).resolve().parents[1]


def _cell(method: str, f_ghz, grid: str = "from_capture", device: str = "cpu"):
    return OmegaConf.create({"method": {"name": method}, "freq": {"f_ghz": f_ghz}, "grid": {"name": grid},
                             "device": device})


def test_time_limit_follows_the_cell():
    fsk = slurm.time_limit_min(_cell("mm2fsk", [72.0, 82.0]), captures=8)
    bp_max_cpu = slurm.time_limit_min(_cell("bp", None, "paper"), captures=8)
    bp_max_gpu = slurm.time_limit_min(_cell("bp", None, "paper", "cuda"), captures=8)
    assert fsk == 15 and bp_max_gpu == 15                        # setup 10 min + 3 x 8 x 0.1-0.2 min, 5-min steps
    assert bp_max_cpu == 10 + 3 * 8 * 30                         # ~20 min per BP_max frame on 2 CPU cores, x 1.5
    assert slurm.time_limit_min(_cell("bp", None, "paper"), captures=16) > bp_max_cpu


def test_node_local_paths_are_refused(monkeypatch, tmp_path):
    monkeypatch.delenv("BENCH_SLURM_LOCAL_PATHS", raising=False)
    with pytest.raises(cli.UserError, match="store.dir: .* node-local file system"):
        slurm.check_shared(Path("/tmp/store"), "store.dir")
    with pytest.raises(cli.UserError, match="node-local"):
        slurm.check_shared(Path("/dev/shm/out"), "hydra.sweep.dir")
    monkeypatch.setattr(slurm, "_mount_type", lambda path: "nfs4")   # a shared file system (not /tmp: the CI's
    slurm.check_shared(Path("/shared/project/store"), "store.dir")   # checkout itself may lie under /tmp)
    monkeypatch.setattr(slurm, "_mount_type", lambda path: "tmpfs")
    with pytest.raises(cli.UserError, match="node-local"):
        slurm.check_shared(Path("/shared/project/store"), "store.dir")
    monkeypatch.setenv("BENCH_SLURM_LOCAL_PATHS", "1")                # a single-node cluster
    slurm.check_shared(Path("/tmp/store"), "store.dir")


@pytest.mark.parametrize("log, cause", [
    ("slurmstepd: error: *** JOB 7 ON n1 CANCELLED AT 2026-11-23T15:00:00 DUE TO TIME LIMIT ***", "timed out"),
    ("slurmstepd: error: Detected 1 oom-kill event(s) in StepId=7.batch", "out of memory"),
    ("slurmstepd: error: *** JOB 7 ON n1 CANCELLED AT 2026-11-23T15:00:00 ***", "cancelled"),
    ("error: /data/x/01_plate/30: dataset root does not exist", "/data/x/01_plate/30: dataset root does not exist"),
    ("", "ended without a result"),
])
def test_a_dead_jobs_cause_comes_from_its_log_without_accounting(monkeypatch, tmp_path, log, cause):
    monkeypatch.setattr(slurm, "slurm_state", lambda job_id: "")        # no sacct, no scontrol record
    (tmp_path / "7_0_log.err").write_text(f"some output\n{log}\n")
    job = SimpleNamespace(job_id="7", paths=SimpleNamespace(stderr=tmp_path / "7_0_log.err",
                                                            stdout=tmp_path / "7_0_log.out"))
    assert cause in slurm.death_cause(job, timeout_min=15, mem_gb=8)


def test_a_temp_folder_of_a_live_process_on_another_host_is_a_leftover(tmp_path):
    """The lock decides, not the process id: a temp folder named with a pid alive here (this test's own, as a
    writer on another node could have) is removed by the next writer holding the root's lock."""
    from bench.synth import SynthConfig, generate_catalogue

    root = tmp_path / "synthetic"
    stale = root / "01_plate" / f".30.tmp-{os.getpid()}-0123abcd"
    (stale / "realsense").mkdir(parents=True)
    results = generate_catalogue(root, [30], ["01_plate"], SynthConfig(frequency_points=16))
    assert [r.status for r in results] == ["generated"] and not stale.exists()


def _slurm_try_skip_reason() -> str | None:
    if os.environ.get("BENCH_SLURM_TRY") != "1":
        return ("opt-in (about 2-15 min: starts SLURM daemons, runs four sweeps): BENCH_SLURM_TRY=1 as root on "
                "Debian/Ubuntu with slurmctld, slurmd and munge installable")
    if os.geteuid() != 0:
        return "starting slurmctld/slurmd needs root"
    if shutil.which("apt-get") is None and shutil.which("slurmctld") is None:
        return "no slurmctld and no apt-get to install it"
    return None


@pytest.mark.slow
@pytest.mark.skipif(_slurm_try_skip_reason() is not None, reason=_slurm_try_skip_reason() or "")
def test_the_slurm_path_on_a_single_node_cluster(tmp_path):
    out = REPO / "outputs" / "slurm-try-test"
    proc = subprocess.run(["bash", str(REPO / "scripts" / "slurm_try.sh"), str(out)], capture_output=True, text=True,
                          timeout=3600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count("ok: ") == 6
