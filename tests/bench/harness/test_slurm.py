"""bench.harness.slurm.launcher: time limits from the cell, the shared-path check, a dead job's cause, temp-folder
ownership by the lock; and, opt-in, the whole SLURM path on a real single-node cluster (scripts/slurm_try.sh)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from omegaconf import OmegaConf

from bench import cli
from bench.harness.slurm import launcher as slurm

REPO = Path(__file__).resolve().parents[3]


@pytest.mark.skipif(os.environ.get("BENCH_SLURM_TRY") == "1", reason="the opt-in real-cluster run keeps SLURM")
def test_the_suite_runs_without_slurms_commands():
    """tests/conftest.py takes them off PATH for the whole session (subprocesses inherit it): a test must fake what
    it touches."""
    from no_slurm import SLURM_COMMANDS

    assert [command for command in SLURM_COMMANDS if shutil.which(command)] == []


def test_path_without_slurm_shadows_only_the_slurm_commands(tmp_path):
    from no_slurm import path_without_slurm

    installed = tmp_path / "usr_bin"
    installed.mkdir()
    for name in ("srun", "sbatch", "python-like-tool"):
        (installed / name).write_text("#!/bin/sh\nexit 0\n")
        (installed / name).chmod(0o755)
    path = path_without_slurm(f"{installed}{os.pathsep}/nonexistent", tmp_path / "shadow")
    assert shutil.which("srun", path=path) is None and shutil.which("sbatch", path=path) is None
    assert Path(shutil.which("python-like-tool", path=path)).resolve() == installed / "python-like-tool"
    assert path.split(os.pathsep)[1] == "/nonexistent"                  # folders without SLURM stay as they are


def test_the_slurm_launcher_without_slurm_is_one_line_before_any_work(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "bench", "-m", "hydra/launcher=slurm_cpu", "cell=mm2fsk_d10",
                           "dataset=maroon", f"dataset.root={tmp_path / 'data'}",
                           f"hydra.sweep.dir={tmp_path / 'sweep'}", f"store.dir={tmp_path / 'store'}"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith("error: hydra/launcher=slurm_cpu: SLURM's sbatch, srun, squeue, scancel not found on "
                                  "PATH") and "hydra/launcher=local" in proc.stderr
    assert not (tmp_path / "data").exists() and not (tmp_path / "store").exists()   # nothing generated or stored


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


def _dead_job(tmp_path, log: str):
    (tmp_path / "7_0_log.err").write_text(f"some output\n{log}\n")
    return SimpleNamespace(job_id="7", paths=SimpleNamespace(stderr=tmp_path / "7_0_log.err",
                                                             stdout=tmp_path / "7_0_log.out"))


@pytest.mark.parametrize("log, cause", [
    ("slurmstepd: error: *** JOB 7 ON n1 CANCELLED AT 2026-11-23T15:00:00 DUE TO TIME LIMIT ***", "timed out"),
    ("slurmstepd: error: Detected 1 oom-kill event(s) in StepId=7.batch", "out of memory"),
    ("slurmstepd-vm: error: StepId=7.0 exceeded memory limit (433430528 > 104857600), being killed\n"
     "slurmstepd-vm: error: *** STEP 7.0 ON vm CANCELLED AT 2026-11-23T17:59:41 ***", "out of memory"),
    ("slurmstepd: error: *** JOB 7 ON n1 CANCELLED AT 2026-11-23T15:00:00 ***", "cancelled"),
    ("error: /data/x/01_plate/30: dataset root does not exist",
     "failed: /data/x/01_plate/30: dataset root does not exist [job log; no accounting]"),
    ("", "ended without a result"),
])
def test_a_dead_jobs_cause_comes_from_its_log_without_accounting(monkeypatch, tmp_path, log, cause):
    monkeypatch.setattr(slurm, "job_record", lambda job_id: slurm.JobRecord())   # no sacct, no scontrol record
    assert cause in slurm.death_cause(_dead_job(tmp_path, log), timeout_min=15, mem_gb=8)


# sacct -n -P -j <id> -o JobID,State,ExitCode,Elapsed,MaxRSS,ReqMem as Debian's SLURM 22.05 printed it on the
# single-node cluster of scripts/slurm_single_node.sh --accounting (memory polled by jobacct_gather/linux with
# OverMemoryKill: the job ends FAILED, its step's MaxRSS above ReqMem)
SACCT = {
    "out of memory (used 413 MiB of 100 MiB) [sacct: FAILED, exit code 9:0]":
        "7|FAILED|9:0|00:00:06||100M\n7.batch|FAILED|9:0|00:00:06|10420K|\n7.0|CANCELLED by 0|0:9|00:00:06|423272K|\n",
    "timed out (time limit 1 min, ran 00:01:12) [sacct: TIMEOUT, exit code 0:0]":
        "7|TIMEOUT|0:0|00:01:12||8G\n7.batch|CANCELLED|0:15|00:01:12|10840K|\n7.0|CANCELLED|0:15|00:01:12|1684K|\n",
    "cancelled (by uid 0) [sacct: CANCELLED by 0, exit code 0:0]": "7|CANCELLED by 0|0:0|00:00:00||8G\n",
    "failed: mm2fsk needs a 2-frequency configuration [sacct: FAILED, exit code 2:0]":
        "7|FAILED|2:0|00:00:09||8G\n7.batch|FAILED|2:0|00:00:09|9000K|\n7.0|FAILED|2:0|00:00:08|301000K|\n",
}


@pytest.mark.parametrize("cause", list(SACCT))
def test_a_dead_jobs_cause_comes_from_sacct(monkeypatch, tmp_path, cause):
    def fake_run(command, **kwargs):
        assert command[0] == "sacct", command          # accounting answers: scontrol is not asked
        return subprocess.CompletedProcess(command, 0, SACCT[cause], "")

    monkeypatch.setattr(slurm.subprocess, "run", fake_run)
    log = "error: mm2fsk needs a 2-frequency configuration" if cause.startswith("failed") else ""
    assert slurm.death_cause(_dead_job(tmp_path, log), timeout_min=1, mem_gb=None) == cause


def test_a_dead_jobs_cause_from_scontrol_when_sacct_has_none(monkeypatch, tmp_path):
    """Without accounting sacct fails; the controller still knows the job for MinJobAge (300 s)."""
    def fake_run(command, **kwargs):
        if command[0] == "sacct":
            return subprocess.CompletedProcess(command, 1, "", "sacct: error: Slurm accounting storage is disabled")
        return subprocess.CompletedProcess(command, 0, "JobId=7 JobName=bench-x JobState=TIMEOUT Reason=TimeLimit "
                                                       "ExitCode=0:0 RunTime=00:01:12 MinMemoryCPU=100M "
                                                       "TRES=cpu=2,mem=200M,node=1", "")

    monkeypatch.setattr(slurm.subprocess, "run", fake_run)
    assert slurm.death_cause(_dead_job(tmp_path, ""), timeout_min=1, mem_gb=8) == \
        "timed out (time limit 1 min, ran 00:01:12) [scontrol: TIMEOUT, exit code 0:0]"


def test_a_job_stopped_at_the_time_limit_warning_is_timed_out_not_done():
    """submitit answers SLURM's warning signal with UncompletedJobError inside the task; Hydra keeps it in a FAILED
    JobReturn that submitit stores as a success (seen on the single-node cluster: sacct said COMPLETED)."""
    from hydra.core.utils import JobReturn, JobStatus
    from submitit.core.utils import UncompletedJobError

    def result(status, value):
        ret = JobReturn(status=status)
        ret._return_value = value
        return ret

    assert slurm.result_cause(result(JobStatus.COMPLETED, None), 1, 30) is None
    warned = result(JobStatus.FAILED, UncompletedJobError("Job not requeued because: timed-out too many times."))
    assert slurm.result_cause(warned, 2, 60).startswith("timed out (time limit 2 min; stopped at SLURM's warning "
                                                        "60 s before it) [job result: Job not requeued")
    assert slurm.result_cause(result(JobStatus.FAILED, KeyError("x")), 2, 60) == "failed: KeyError: 'x' [job result]"


def test_a_job_sbatch_refuses_is_one_error_line_and_the_sweeps_jobs_are_cancelled(capsys):
    from submitit.core.utils import FailedJobError

    cancelled = []
    submitted = [SimpleNamespace(cancel=lambda check: cancelled.append("41"))]
    with pytest.raises(SystemExit) as exit_info:
        slurm.refused("bp_full", FailedJobError("sbatch: error: Batch job submission failed: Invalid partition name "
                                                "specified"), submitted)
    assert exit_info.value.code == 2 and cancelled == ["41"]
    assert capsys.readouterr().err == ("error: hydra.launcher: sbatch refused the job of bp_full: sbatch: error: "
                                       "Batch job submission failed: Invalid partition name specified (the 1 job(s) "
                                       "submitted before it were cancelled)\n")


def test_jobs_are_reported_not_awaited_forever_when_squeue_stops_answering(monkeypatch, tmp_path):
    monkeypatch.setattr(slurm, "listed_jobs", lambda: None)             # the controller is down
    monkeypatch.setattr(slurm, "CONTROLLER_LOST_S", 0.0)
    launcher = object.__new__(slurm.CheckedSlurmLauncher)
    job = SimpleNamespace(job_id="7", paths=SimpleNamespace(result_pickle=tmp_path / "7_0_result.pkl"))
    cfg = OmegaConf.create({"hydra": {"sweep": {"dir": str(tmp_path), "subdir": "0_cell"}}})
    returns, missing = launcher._wait([(0, "mm2fsk_d8", 15, job, cfg)])
    assert returns == [] and [cell for cell, _ in missing] == ["mm2fsk_d8"]
    assert "job 7: no answer from squeue for 0 min" in missing[0][1]


def test_a_temp_folder_of_a_live_process_on_another_host_is_a_leftover(tmp_path):
    """The lock decides, not the process id: a temp folder named with a pid alive here (this test's own, as a
    writer on another node could have) is removed by the next writer holding the root's lock."""
    from bench.synth import SynthConfig, generate_catalogue

    root = tmp_path / "synthetic"
    stale = root / "01_plate" / f".30.tmp-{os.getpid()}-0123abcd"
    (stale / "realsense").mkdir(parents=True)
    results = generate_catalogue(root, [30], ["01_plate"], SynthConfig(frequency_points=16))
    assert [r.status for r in results] == ["generated"] and not stale.exists()


def _slurm_try_skip_reason(accounting: bool) -> str | None:
    if os.environ.get("BENCH_SLURM_TRY") != "1":
        return ("opt-in (about 5-10 min per mode: starts SLURM daemons, runs eight small sweeps): BENCH_SLURM_TRY=1 as "
                "root on Debian/Ubuntu with slurmctld, slurmd and munge installable"
                + (", and slurmdbd and mariadb-server for accounting" if accounting else ""))
    if os.geteuid() != 0:
        return "starting slurmctld/slurmd needs root"
    needed = ["slurmctld"] + (["slurmdbd", "mariadbd"] if accounting else [])
    if shutil.which("apt-get") is None and any(shutil.which(daemon) is None for daemon in needed):
        return f"no apt-get to install {' and '.join(needed)}"
    return None


@pytest.mark.slow
@pytest.mark.parametrize("accounting", [
    pytest.param(False, marks=pytest.mark.skipif(_slurm_try_skip_reason(False) is not None,
                                                 reason=_slurm_try_skip_reason(False) or "")),
    pytest.param(True, marks=pytest.mark.skipif(_slurm_try_skip_reason(True) is not None,
                                                reason=_slurm_try_skip_reason(True) or ""))],
    ids=["no-accounting", "accounting"])
def test_the_slurm_path_on_a_single_node_cluster(accounting):
    """scripts/slurm_try.sh: sweep, re-run from the store, a cancelled job resumed, a job failing with its own
    error, jobs killed for memory, a job killed at its time limit and one stopped at the limit's warning signal;
    each cause read from sacct with accounting, else from scontrol or the job's log (the warning: the job's result).
    The daemons are stopped afterwards (their jobs' CPU load counts against everyone's timings)."""
    out = REPO / "outputs" / f"slurm-try-test-{'accounting' if accounting else 'none'}"
    try:
        proc = subprocess.run(["bash", str(REPO / "scripts" / "slurm_try.sh"),
                               *(["--accounting"] if accounting else []), str(out)],
                              capture_output=True, text=True, timeout=3600)
    finally:
        subprocess.run(["bash", str(REPO / "scripts" / "slurm_single_node.sh"), "stop"], capture_output=True,
                       timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count("ok: ") == 18, proc.stdout


def test_a_jobs_absurd_setting_is_one_line_before_anything_is_submitted(tmp_path):
    """Each job's configuration is checked (bench.harness.validate) before sbatch sees it; fakes of every SLURM
    command the launcher touches, sbatch's leaving a mark if it is called."""
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "sbatch").write_text(f'#!/bin/sh\ntouch {tmp_path / "sbatch-called"}\necho "Submitted batch job 7"\n')
    (fake / "sinfo").write_text("#!/bin/sh\necho 16\n")
    for name in ("srun", "squeue", "scancel"):
        (fake / name).write_text("#!/bin/sh\nexit 0\n")
    for tool in fake.iterdir():
        tool.chmod(0o755)
    env = {**os.environ, "PATH": f"{fake}:{os.environ['PATH']}", "BENCH_SLURM_LOCAL_PATHS": "1"}
    proc = subprocess.run([sys.executable, "-m", "bench", "-m", "hydra/launcher=slurm_cpu", "cell=mm2fsk_d10",
                           "threshold_db=14,-3", "dataset=maroon", f"dataset.root={tmp_path}",
                           f"hydra.sweep.dir={tmp_path / 'sweep'}", f"store.dir={tmp_path / 'store'}"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env)
    assert proc.returncode == 2 and proc.stderr == "error: threshold_db=-3: must be a number >= 0 and <= 1529.23\n"
    assert not (tmp_path / "sbatch-called").exists()
