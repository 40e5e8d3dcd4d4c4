"""The in-process launcher (configs/hydra/launcher/inprocess.yaml, the default): a multirun's jobs one after another
in this process, as Hydra's basic launcher runs them, with Hydra's per-job set-up cut to what a job reads.

Hydra's `run_job` copies the job's `hydra` node three times (two `HydraConfig.set_config` calls and a deep copy for
the job's return value), deep-copies the whole configuration to remove `hydra` from the job's copy and writes the
three .hydra/*.yaml files with PyYAML's pure-Python emitter before the job starts: ~40 ms a job on two loaded cores
(docs/measurements/sweep.md). Here: one `set_config`, the job's configuration copied without its `hydra` node
(`OmegaConf.masked_copy`, its flags kept), the return value holding the job's own Hydra configuration (a new object
per job, which nothing edits), and the .hydra/*.yaml files (the same bytes) written by a background thread from
plain containers taken on this thread; the launch waits for them before it returns (and on an error or Ctrl-C). The
rest is Hydra's: the job's folder, its logging (app.log), `hydra.job.env_set`, `chdir`, the callbacks, a failed
job's error. Jobs in other processes or on a cluster: hydra/launcher=local (joblib), submitit_local, slurm_cpu,
slurm_gpu.
"""
from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import yaml
from hydra import version
from hydra.core.hydra_config import HydraConfig
from hydra.core.utils import (
    JobReturn,
    JobRuntime,
    JobStatus,
    _flush_loggers,
    configure_log,
    env_override,
    filter_overrides,
    setup_globals,
)
from hydra.plugins.launcher import Launcher
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig, OmegaConf, open_dict, read_write
from omegaconf._utils import get_omega_conf_dumper

from bench.harness import stages

log = logging.getLogger(__name__)


def _yaml(container) -> str:
    """`OmegaConf.to_yaml`'s text of a node already made a container (its dumper, its options)."""
    return yaml.dump(container, default_flow_style=False, allow_unicode=True, sort_keys=False,
                     Dumper=get_omega_conf_dumper())


def _write_files(folder: Path, containers: dict[str, object]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, container in containers.items():
        (folder / name).write_text(_yaml(container), encoding="utf-8")


def _task_config(config: DictConfig) -> DictConfig:
    """The job's configuration without its `hydra` node, as Hydra's deep copy with `hydra` deleted: the same nodes
    (copied) and the root's struct and read-only flags."""
    task = OmegaConf.masked_copy(config, [key for key in config if key != "hydra"])
    OmegaConf.set_struct(task, OmegaConf.is_struct(config))
    OmegaConf.set_readonly(task, OmegaConf.is_readonly(config))
    return task


def run_job_here(hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig,
                 writer: ThreadPoolExecutor, written: list[Future]) -> JobReturn:
    """hydra.core.utils.run_job for a sweep's job (`hydra.sweep.dir`/`subdir`), with the set-up of the module doc;
    the .hydra files are submitted to `writer` (their futures appended to `written`)."""
    stages.begin("launch")
    callbacks = hydra_context.callbacks
    old_cwd = os.getcwd()
    hydra_config = HydraConfig.instance()
    previous = hydra_config.cfg
    hydra_config.set_config(config)     # once: interpolations in the job's folder name read this job's values
    output_dir = os.path.join(str(OmegaConf.select(config, "hydra.sweep.dir")),
                              str(OmegaConf.select(config, "hydra.sweep.subdir")))
    for runtime in (config.hydra.runtime, hydra_config.cfg.hydra.runtime):   # the job's and HydraConfig's copy
        with read_write(runtime), open_dict(runtime):
            runtime.output_dir = os.path.abspath(output_dir)
    chdir = False
    try:
        ret = JobReturn()
        task_cfg = _task_config(config)
        ret.cfg = task_cfg
        ret.hydra_cfg = hydra_config.cfg
        ret.overrides = OmegaConf.to_container(config.hydra.overrides.task)
        Path(output_dir).mkdir(parents=True, exist_ok=True)
        chdir = config.hydra.job.chdir
        if chdir is None:                          # Hydra's rule: False from version_base 1.2 (this app's is 1.3)
            chdir = not version.base_at_least("1.2")
        if chdir:
            os.chdir(output_dir)
            ret.working_dir = output_dir
        else:
            ret.working_dir = os.getcwd()
        configure_log(config.hydra.job_logging, config.hydra.verbose)
        if config.hydra.output_subdir is not None:
            containers = {"config.yaml": OmegaConf.to_container(task_cfg, enum_to_str=True),
                          "hydra.yaml": OmegaConf.to_container(hydra_config.cfg, enum_to_str=True),
                          "overrides.yaml": ret.overrides}
            folder = Path(config.hydra.runtime.output_dir) / str(config.hydra.output_subdir)
            written.append(writer.submit(_write_files, folder, containers))
        with env_override(config.hydra.job.env_set):
            callbacks.on_job_start(config=config, task_function=task_function)
            stages.end()
            try:
                ret.return_value = task_function(task_cfg)
                ret.status = JobStatus.COMPLETED
            except Exception as e:  # noqa: BLE001 -- as Hydra: the job's error is its return value
                ret.return_value = e
                ret.status = JobStatus.FAILED
            stages.begin("launch")
        ret.task_name = JobRuntime.instance().get("name")
        _flush_loggers()
        callbacks.on_job_end(config=config, job_return=ret)
        return ret
    finally:
        hydra_config.cfg = previous
        if chdir:
            os.chdir(old_cwd)
        stages.end()


class InProcessLauncher(Launcher):
    """Hydra's BasicLauncher (same jobs, numbering, folders, files, logs) with the lean per-job set-up above."""

    def __init__(self) -> None:
        super().__init__()
        self.config: DictConfig | None = None
        self.task_function: TaskFunction | None = None
        self.hydra_context: HydraContext | None = None

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.config = config
        self.hydra_context = hydra_context
        self.task_function = task_function

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        setup_globals()
        assert self.hydra_context is not None and self.config is not None and self.task_function is not None
        configure_log(self.config.hydra.hydra_logging, self.config.hydra.verbose)
        Path(str(self.config.hydra.sweep.dir)).mkdir(parents=True, exist_ok=True)
        log.info(f"Launching {len(job_overrides)} jobs locally")
        runs: list[JobReturn] = []
        written: list[Future] = []
        with ThreadPoolExecutor(1, thread_name_prefix="hydra-files") as writer:
            try:
                for idx, overrides in enumerate(job_overrides, initial_job_idx):
                    log.info(f"\t#{idx} : {' '.join(filter_overrides(overrides))}")
                    sweep_config = self.hydra_context.config_loader.load_sweep_config(self.config, list(overrides))
                    with open_dict(sweep_config):
                        sweep_config.hydra.job.id = idx
                        sweep_config.hydra.job.num = idx
                    runs.append(run_job_here(self.hydra_context, self.task_function, sweep_config, writer, written))
                    configure_log(self.config.hydra.hydra_logging, self.config.hydra.verbose)
            finally:
                writer.shutdown(wait=True)
        for future in written:
            future.result()          # a file that could not be written: its error, as Hydra's would be
        return runs

