"""SLURM sweeps that hold on real clusters: hydra-submitit-launcher's SLURM launcher, one job per cell.

`hydra/launcher=slurm_cpu` / `slurm_gpu` (configs/hydra/launcher/) use `CheckedSlurmLauncher`, which, in the
submitting process and before anything is submitted:

* ends in one line where SLURM's commands are not on PATH (a machine without SLURM), and where any job's setting
  is out of range (bench.harness.validate), before any data is prepared;
* checks that the sweep directory, the store, the dataset root and submitit's folder are absolute-able paths on a
  file system the nodes can share (not /tmp, /var/tmp, /dev/shm, /run or a tmpfs: a node's private disk), unless
  `BENCH_SLURM_LOCAL_PATHS=1` (a single-node cluster); the jobs get them as absolute paths, so a job that starts in
  another directory still writes where the merge looks;
* generates the synthetic captures the sweep needs, once (jobs then find them cached and never generate);
* points every job at one Warp kernel cache beside the store (`WARP_CACHE_PATH`; Warp >= 1.2 builds into a temp
  folder and renames it, so concurrent jobs may share it), instead of one /tmp folder per job;
* sizes each cell's job: its name (`bench-<cell>`, `bench-<cell>-offset_mm=2` with parameters), GPUs (1 for
  device=cuda, none otherwise), CPUs per task (at most what a node of the partition has: more would leave the job
  pending forever), with `mem_gb: 0` its
  memory from the cell (bench.harness.resources), and, with `timeout_min: 0`, a time limit from the cell
  (`time_limit_min`).

Then it waits for every job without relying on accounting: a job is done when submitit's result file appears and
holds a finished cell, and dead when SLURM no longer lists it (squeue) and no result came; its cause comes from
`sacct` (accounting: state, exit code, run time, the steps' MaxRSS against ReqMem) or `scontrol` (the controller),
and from its log (time limit, cancellation, out of memory, the job's own `error:` line), or from its result (a job
stopped at SLURM's time-limit warning); the message says which it read. When any job did not finish, the rows of
the jobs that did are merged (bench.report.merge), each missing cell is named with its cause on stderr, and the sweep
exits 1. A re-run of the same command recomputes only the missing cells (the store). A job sbatch refuses (a
partition, account or GPU the cluster does not have) ends the sweep in one error line, exit 2, the jobs submitted
before it cancelled; squeue failing for CONTROLLER_LOST_S names the pending jobs instead of waiting forever.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from hydra.core.singleton import Singleton
from hydra.core.utils import JobReturn, JobStatus, filter_overrides
from omegaconf import DictConfig, OmegaConf, open_dict

from bench import cli
from bench.harness import validate
from bench.harness.identity import params_string
from bench.harness.resources import job_mem_gb
from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf
from hydra_plugins.hydra_submitit_launcher.submitit_launcher import SlurmLauncher

SLURM_NEEDED = ("sbatch", "srun", "squeue", "scancel")   # submit, submitit's job script, wait, cancel
LOCAL_PREFIXES = ("/tmp", "/var/tmp", "/dev/shm", "/run")
LOCAL_FS_TYPES = {"tmpfs", "ramfs", "devtmpfs"}
POLL_S = 2.0
CONTROLLER_LOST_S = 900.0   # squeue failing this long: report the pending jobs instead of waiting forever
GONE_GRACE_S = 15.0         # a finished job's result file may show on a shared file system a little later
# Minutes per capture frame on one node, generous (docs/measurements/performance.md "The demo's cost" and
# docs/measurements/gpu.md measured ~20 min for BP_max on the paper grid on 2 CPU cores, ~1 s for the FSK methods):
# (method, many frequencies?, grid, device).
FRAME_MINUTES = {("bp", True, "paper", "cpu"): 30.0, ("bp", False, "paper", "cpu"): 4.0,
                 ("bp", True, "paper", "cuda"): 0.2, ("bp", False, "paper", "cuda"): 0.1}
DEFAULT_FRAME_MINUTES = {"bp": 1.0, "2fsk": 0.1, "3fsk": 0.1, "mm2fsk": 0.1}
SETUP_MINUTES = 10          # Python start, imports, reading the captures, Warp compilation on a cold cache


def time_limit_min(cfg: DictConfig, captures: int) -> int:
    """A job's time limit (minutes) from its cell: frames x FRAME_MINUTES x 3 + SETUP_MINUTES, in 5-minute steps."""
    method, freqs = str(cfg.method.name), cfg.freq.f_ghz
    many = freqs is None or len(freqs) > 3
    key = (method, many, str(cfg.grid.name), "cuda" if str(cfg.device) == "cuda" else "cpu")
    per_frame = FRAME_MINUTES.get(key, DEFAULT_FRAME_MINUTES.get(method, 1.0))
    return int(5 * math.ceil((SETUP_MINUTES + 3 * per_frame * max(captures, 1)) / 5))


def _mount_type(path: Path) -> str:
    """File system type of the mount holding `path` (/proc/mounts; '' where unknown)."""
    best, kind = "", ""
    try:
        for line in Path("/proc/mounts").read_text().splitlines():
            fields = line.split()
            mount = fields[1].replace("\\040", " ")
            if str(path).startswith(mount.rstrip("/") + "/") or str(path) == mount:
                if len(mount) > len(best):
                    best, kind = mount, fields[2]
    except OSError:
        return ""
    return kind


def check_slurm_commands(launcher: str) -> None:
    """One error line (exit 2) before anything is prepared where SLURM's commands are not on PATH (a machine that
    is not a SLURM submit host): which are missing, and how to run the sweep here instead."""
    missing = [command for command in SLURM_NEEDED if shutil.which(command) is None]
    if missing:
        cli.fail(f"hydra/launcher={launcher}: SLURM's {', '.join(missing)} not found on PATH (this machine is not a "
                 "SLURM submit host); run the sweep on this machine with hydra/launcher=local (parallel jobs) or "
                 "without hydra/launcher (one job after another)")


def check_shared(path: Path, what: str) -> None:
    """A UserError unless `path` lies on a file system other nodes can see (heuristic: not node-local)."""
    if os.environ.get("BENCH_SLURM_LOCAL_PATHS") == "1":
        return
    real = Path(os.path.realpath(path))
    if any(str(real) == p or str(real).startswith(p + "/") for p in LOCAL_PREFIXES) or \
            _mount_type(real) in LOCAL_FS_TYPES:
        raise cli.UserError(what, f"{real} is on a node-local file system; SLURM jobs on other nodes cannot see "
                                  "it: use a shared path (or BENCH_SLURM_LOCAL_PATHS=1 on a single-node cluster)")


def node_cpus(partition: str | None) -> int | None:
    """The most CPUs one node of the partition has (sinfo), or None where sinfo cannot say."""
    command = ["sinfo", "-h", "-o", "%c"] + (["-p", partition] if partition else [])
    try:
        out = subprocess.run(command, capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.TimeoutExpired):
        return None
    values = [int(v.rstrip("+")) for v in out.split() if v.rstrip("+").isdigit()]
    return max(values) if values else None


def listed_jobs() -> set[str] | None:
    """Job ids SLURM still lists (pending or running), or None where squeue fails."""
    try:
        proc = subprocess.run(["squeue", "-h", "-o", "%i"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return set(proc.stdout.split()) if proc.returncode == 0 else None


@dataclass
class JobRecord:
    """What SLURM still knows of an ended job: `source` is 'sacct' (accounting), 'scontrol' (the controller keeps
    an ended job for MinJobAge, 300 s by default) or '' (neither); sizes in bytes, 0 where unknown."""
    source: str = ""
    state: str = ""              # e.g. FAILED, TIMEOUT, OUT_OF_MEMORY, "CANCELLED by 0"
    exit_code: str = ""          # <exit status>:<signal>
    elapsed: str = ""            # [D-]HH:MM:SS
    max_rss_b: int = 0           # largest MaxRSS of the job's steps
    req_mem_b: int = 0           # memory asked for per node


_UNITS = {"": 1, "K": 2 ** 10, "M": 2 ** 20, "G": 2 ** 30, "T": 2 ** 40}


def _bytes(text: str, default_unit: str) -> int:
    """sacct's `423272K`, `200M` (SLURM 22.05's ReqMem: per node, also for --mem-per-cpu; older ones append n/c)
    in bytes; 0 where empty."""
    found = re.fullmatch(r"([\d.]+)([KMGT]?)[nc]?", text.strip())
    return int(float(found.group(1)) * _UNITS[found.group(2) or default_unit]) if found else 0


def job_record(job_id: str) -> JobRecord:
    """The job's end as sacct records it (the job's line and the largest MaxRSS of its steps), else scontrol's."""
    try:
        proc = subprocess.run(["sacct", "-n", "-P", "-j", job_id, "-o", "JobID,State,ExitCode,Elapsed,MaxRSS,ReqMem"],
                              capture_output=True, text=True, timeout=30)
        rows = [line.split("|") for line in proc.stdout.splitlines() if line.count("|") == 5] \
            if proc.returncode == 0 else []
    except (OSError, subprocess.TimeoutExpired):
        rows = []
    job = [row for row in rows if row[0] == job_id]
    if job:
        _, state, exit_code, elapsed, _, req_mem = job[0]
        return JobRecord("sacct", state, exit_code, elapsed, max(_bytes(row[4], "K") for row in rows),
                         _bytes(req_mem, "M"))
    try:
        proc = subprocess.run(["scontrol", "-o", "show", "job", job_id], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return JobRecord()
    fields = dict(re.findall(r"(\w+)=(\S*)", proc.stdout)) if proc.returncode == 0 else {}
    if "JobState" not in fields:
        return JobRecord()
    mem = re.search(r"(?:^|,)mem=([^,]+)", fields.get("TRES", ""))   # per node, also for --mem-per-cpu
    return JobRecord("scontrol", fields["JobState"], fields.get("ExitCode", ""), fields.get("RunTime", ""), 0,
                     _bytes(mem.group(1) if mem else "", "M"))


def death_cause(job, timeout_min: int, mem_gb: int | None) -> str:
    """Why a job ended without a result, and where that was read: sacct's record where accounting exists (a job
    killed by slurmd's memory polling ends FAILED there, its steps' MaxRSS above ReqMem), scontrol's, and the job's
    log (time limit, cancellation, memory, the job's own `error:` line)."""
    record = job_record(str(job.job_id))
    log = ""
    for path in (job.paths.stderr, job.paths.stdout):
        if Path(path).is_file():
            log += Path(path).read_text(errors="replace")[-20000:]
    errors = [line for line in log.splitlines() if line.startswith("error:")]
    over_memory = record.req_mem_b and record.max_rss_b > record.req_mem_b
    mib = 2 ** 20
    if "TIMEOUT" in record.state or "DUE TO TIME LIMIT" in log:
        ran = f", ran {record.elapsed}" if record.elapsed else ""
        cause = f"timed out (time limit {timeout_min} min{ran})"
    elif "OUT_OF_MEMORY" in record.state or over_memory or \
            re.search(r"oom[-_ ]kill|out of memory|exceeded (job )?memory limit", log, re.IGNORECASE):
        limit = f"{record.req_mem_b / mib:.0f} MiB" if record.req_mem_b else f"mem_gb={mem_gb}"
        used = f"used {record.max_rss_b / mib:.0f} MiB of {limit}" if over_memory else f"limit {limit}"
        cause = f"out of memory ({used})"
    elif "CANCELLED" in record.state or "CANCELLED" in log:
        by = re.search(r"CANCELLED by (\d+)", record.state)
        cause = f"cancelled ({f'by uid {by.group(1)}' if by else 'scancel or an administrator'})"
    elif errors:
        cause = f"failed: {errors[-1].removeprefix('error:').strip()}"
    elif record.state:
        cause = "ended without a result"
    else:
        return "ended without a result (killed, node failure or out of memory; no accounting here to say which)"
    state = f"{record.state}, exit code {record.exit_code}" if record.exit_code else record.state
    return f"{cause} [{f'{record.source}: {state}' if record.source else 'job log; no accounting'}]"


def refused(cell: str, err: Exception, submitted: list) -> None:
    """One error line (exit 2) for a job sbatch refused (a partition, account, GPU or memory request the cluster
    does not have, or no controller to ask); the jobs this sweep submitted before it are cancelled, so that none
    runs unseen."""
    for job in submitted:
        job.cancel(check=False)
    reason = " ".join((str(err).strip().splitlines() or ["sbatch failed"])[-1].split())
    cancelled = f" (the {len(submitted)} job(s) submitted before it were cancelled)" if submitted else ""
    cli.fail(f"hydra.launcher: sbatch refused the job of {cell}: {reason}{cancelled}")


def result_cause(result: JobReturn, timeout_min: int, signal_delay_s: int) -> str | None:
    """Why a job that returned a result did not finish its cell, or None when it did. A job still running when
    SLURM's time-limit warning comes (submitit's --signal, `signal_delay_s` before the limit) raises submitit's
    UncompletedJobError in the task (the launcher never requeues: max_num_timeout 0); Hydra keeps that exception
    in a FAILED JobReturn, which submitit stores as a successful result, so sacct says COMPLETED."""
    from submitit.core.utils import UncompletedJobError  # here: Hydra's plugin scan imports this module in every run

    if result.status != JobStatus.FAILED:
        return None
    err = result._return_value       # the JobReturn's exception (its `return_value` property re-raises it)
    text = " ".join(str(err).split())
    if isinstance(err, UncompletedJobError) and "timed-out" in text:
        return (f"timed out (time limit {timeout_min} min; stopped at SLURM's warning {signal_delay_s} s before "
                f"it) [job result: {text}]")
    return f"failed: {type(err).__name__}: {text} [job result]"


class CheckedSlurmLauncher(SlurmLauncher):
    """hydra-submitit's SLURM launcher with the checks, sizing and failure handling of the module doc."""

    def _paths(self) -> dict[str, Path]:
        cfg = self.config
        paths = {"hydra.sweep.dir": Path(str(cfg.hydra.sweep.dir)),
                 "hydra.launcher.submitit_folder": Path(str(self.params["submitit_folder"])),
                 "dataset.root": Path(str(cfg.dataset.root))}
        if cfg.store.dir is not None:
            paths["store.dir"] = Path(str(cfg.store.dir))
        return {key: path.absolute() for key, path in paths.items()}

    def _prepare_data(self) -> None:
        """Generate the synthetic captures once, here, before any job starts (bench.harness.app's rule for when)."""
        from bench.harness.app import ensure_synthetic, synthetic_asked

        overrides = list(self.config.hydra.overrides.task)
        if synthetic_asked(overrides):
            print(f"preparing the synthetic captures in {self._paths()['dataset.root']} before submitting",
                  flush=True)
            ensure_synthetic(self.config.dataset, self._paths()["dataset.root"], self.config.synth)

    def launch(self, job_overrides, initial_job_idx: int) -> list[JobReturn]:
        import submitit
        from submitit.core.utils import FailedJobError

        check_slurm_commands(self.config.hydra.runtime.choices.get("hydra/launcher") or "slurm")
        paths = self._paths()
        try:
            for key, path in paths.items():
                check_shared(path, key)
        except cli.UserError as err:
            cli.fail(str(err))
        absolute = [f"hydra.sweep.dir={paths['hydra.sweep.dir']}", f"dataset.root={paths['dataset.root']}"]
        if "store.dir" in paths:
            absolute.append(f"store.dir={paths['store.dir']}")
        job_configs = self._job_configs(job_overrides, initial_job_idx, absolute)
        self._prepare_data()
        if "store.dir" in paths:
            os.environ.setdefault("WARP_CACHE_PATH", str(paths["store.dir"] / "warp-cache"))
        executor = submitit.AutoExecutor(folder=str(paths["hydra.launcher.submitit_folder"]), cluster="slurm",
                                         slurm_max_num_timeout=int(self.params.get("max_num_timeout", 0)))
        generic = set(OmegaConf.structured(BaseQueueConf).keys())       # the rest are slurm_<name> (as submitit's)
        fixed = {k if k in generic else f"slurm_{k}": v for k, v in self.params.items()
                 if k not in {"submitit_folder", "max_num_timeout", "timeout_min", "gpus_per_node", "name",
                              "array_parallelism", "cpus_per_task", "mem_gb"} and v not in (None, {}, [])}
        cpus = int(self.params.get("cpus_per_task") or 1)
        available = node_cpus(self.params.get("partition"))
        if available is not None and cpus > available:
            print(f"cpus_per_task={cpus} is more than a node of the partition has ({available}): using {available}",
                  flush=True)
            cpus = available
        paths["hydra.sweep.dir"].mkdir(parents=True, exist_ok=True)
        jobs, self._mem_gb = [], {}
        for idx, overrides, cfg in job_configs:
            cell = cfg.hydra.runtime.choices.get("cell") or f"{cfg.method.name}_{cfg.freq.name}_{cfg.prior.name}"
            params = params_string(list(cfg.hydra.overrides.task))        # a parameter sweep's jobs apart
            cell += f"-{params.replace(' ', ',')}" if params else ""
            captures = len(cfg.dataset.captures) if cfg.dataset.captures is not None else _count(paths)
            timeout = int(self.params.get("timeout_min") or 0) or time_limit_min(cfg, captures)
            gpus = 1 if str(cfg.device) == "cuda" else None
            mem_gb = job_mem_gb(cfg, captures, self.params.get("mem_gb"))       # 0: from the cell, null: not asked
            executor.update_parameters(**fixed, name=f"bench-{cell}", timeout_min=timeout, cpus_per_task=cpus,
                                       gpus_per_node=gpus, **({} if mem_gb is None else {"mem_gb": mem_gb}))
            try:
                job = executor.submit(self, overrides, "hydra.sweep.dir", idx, f"job_id_for_{idx}",
                                      Singleton.get_state())
            except FailedJobError as err:   # sbatch refused it: a setting the user can fix
                refused(cell, err, [entry[3] for entry in jobs])
            memory = "" if mem_gb is None else f", {mem_gb} GB"
            print(f"[submitted {idx + 1}/{len(job_overrides)}] {cell}: job {job.job_id}, {timeout} min, "
                  f"{cpus} CPUs{memory}{', 1 GPU' if gpus else ''} ({' '.join(filter_overrides(overrides))})",
                  flush=True)
            jobs.append((idx, cell, timeout, job, cfg))
            self._mem_gb[job.job_id] = mem_gb
        returns, missing = self._wait(jobs)
        if missing:
            self._report_missing(missing)
        return returns

    def _job_configs(self, job_overrides, initial_job_idx: int, absolute: list[str]
                     ) -> list[tuple[int, list, DictConfig]]:
        """(job number, overrides, configuration) of every job, each checked (bench.harness.validate) before any
        data is prepared or any job submitted: one line and exit 2 for the first setting out of range."""
        configs = []
        for idx, overrides in enumerate(job_overrides, start=initial_job_idx):
            overrides = [*overrides, *absolute]
            cfg = self.hydra_context.config_loader.load_sweep_config(self.config, overrides)
            try:
                validate.check(cfg, memory=False)        # the nodes' memory is not this machine's
            except cli.UserError as err:
                cli.fail(str(err))
            with open_dict(cfg.hydra.job):
                cfg.hydra.job.num = idx          # the job folder's name (hydra.sweep.subdir) needs it
            configs.append((idx, overrides, cfg))
        return configs

    def _wait(self, jobs) -> tuple[list[JobReturn], list[tuple[str, str]]]:
        """Results of the jobs that finished, and (cell, cause) of those that did not."""
        pending, returns, missing, gone_since = list(jobs), [], [], {}
        answered = time.monotonic()
        while pending:
            listed = listed_jobs()
            if listed is not None:
                answered = time.monotonic()
            for entry in list(pending):
                idx, cell, timeout, job, cfg = entry
                if Path(job.paths.result_pickle).exists():
                    pending.remove(entry)
                    try:
                        result = job.results()[0]
                    except Exception as err:   # noqa: BLE001 -- submitit re-raises the job's own exception
                        missing.append((cell, f"job {job.job_id} failed: {str(err).strip().splitlines()[-1]}"))
                        continue
                    cause = result_cause(result, timeout, int(self.params.get("signal_delay_s") or 0))
                    if cause is None:
                        returns.append(result)
                        print(f"[done] {cell}: job {job.job_id}", flush=True)
                    else:
                        missing.append((cell, f"job {job.job_id} {cause}; log: {job.paths.stderr}"))
                elif listed is not None and str(job.job_id) not in listed:
                    first = gone_since.setdefault(job.job_id, time.monotonic())
                    if time.monotonic() - first > GONE_GRACE_S:
                        pending.remove(entry)
                        cause = death_cause(job, timeout, self._mem_gb.get(job.job_id))
                        missing.append((cell, f"job {job.job_id} {cause}; log: {job.paths.stderr}"))
            if pending and time.monotonic() - answered > CONTROLLER_LOST_S:   # waiting on would wait forever
                missing += [(cell, f"job {job.job_id}: no answer from squeue for {CONTROLLER_LOST_S / 60:.0f} min "
                                   "(SLURM's controller down?); the job may still run: see squeue, or run the same "
                                   "command again later") for _, cell, _, job, _ in pending]
                break
            if pending:
                time.sleep(POLL_S)
        for _, cell, _, _, cfg in jobs:
            job_dir = Path(str(cfg.hydra.sweep.dir)) / str(cfg.hydra.sweep.subdir)
            if not (job_dir / "results.csv").is_file() and cell not in {c for c, _ in missing}:
                missing.append((cell, f"finished but wrote no {job_dir}/results.csv"))
        return returns, missing

    def _report_missing(self, missing: list[tuple[str, str]]) -> None:
        """Merge what finished, name each missing cell and its cause, exit 1."""
        from hydra.utils import instantiate

        root = self._paths()["hydra.sweep.dir"]
        try:   # the sweep's own merge callback (configs/config.yaml hydra.callbacks.merge): the harness names no report
            instantiate(self.config.hydra.callbacks.merge).on_multirun_end(self.config)
            merged = f"the rows of the finished cells are merged into {root}/results.csv"
        except FileNotFoundError:
            merged = "no cell finished: nothing to merge"
        for cell, cause in missing:
            print(f"error: {cell}: {cause}", file=sys.stderr, flush=True)
        print(f"error: {len(missing)} cell(s) did not finish; {merged}; run the same command again to compute only "
              "the missing cells (the store keeps the finished ones)", file=sys.stderr, flush=True)
        sys.exit(1)


def _count(paths: dict[str, Path]) -> int:
    from bench.maroon import reader

    try:
        return len(reader.discover_captures(paths["dataset.root"]))
    except Exception:   # noqa: BLE001 -- only a time estimate: unknown counts as one capture
        return 1


