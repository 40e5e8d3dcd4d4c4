"""Hydra's basic sweeper, composing each job's configuration once instead of twice.

Hydra's BasicSweeper composes every job of a batch to check it (`validate_batch_is_legal`: a typo fails before any
job runs) and its launcher composes each job again before running it. Composition costs 0.2 s on a quiet 2-core
machine and 1.7 s on a loaded one, per job and per pass. Here the checked configurations are kept and handed to
the launcher when it asks for the same overrides, so each job is composed once. Launchers that compose in another
process (joblib, submitit) compose there as before: the kept configurations are not sent along.

A batch of several jobs is composed by forked worker processes, one per core, on machines of at least MIN_CORES
cores (a composed configuration comes back pickled: ~1.5 ms to read against 60-200 ms to compose): 13 jobs of
Table III take ~1.2 s one after another on the H100 host's CPU. Where that fails (a composition error, e.g. a typo
in an override) the batch is composed here, one job after another, and the error is Hydra's own as before.
"""
from __future__ import annotations

import multiprocessing
import os
import pickle
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor

from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.types import HydraContext
from omegaconf import DictConfig

from bench.harness import stages
from methods.domain.host import usable_cores


class _ComposedOnce:
    """A config loader that returns a configuration composed by `keep` to the first `load_sweep_config` asking
    for the same overrides (then forgets it: the launcher edits what it gets); everything else is the loader's."""

    def __init__(self, loader):
        self._loader = loader
        self._kept: dict[tuple[str, ...], DictConfig] = {}

    def _compose(self, master_config: DictConfig, overrides: Sequence[str]) -> DictConfig:
        with stages.stage("composition"):
            return self._loader.load_sweep_config(master_config, list(overrides))

    def keep(self, master_config: DictConfig, overrides: Sequence[str]) -> None:
        self._kept[tuple(overrides)] = self._compose(master_config, overrides)

    def keep_all(self, master_config: DictConfig, batch: Sequence[Sequence[str]]) -> None:
        """`keep` for every job of the batch, composed by forked workers where there are several jobs and cores
        (module doc); one after another here where that is not possible or fails."""
        workers = min(len(batch), usable_cores())
        if workers > 1 and usable_cores() >= MIN_CORES and hasattr(os, "fork"):
            with stages.stage("composition"):
                composed = _compose_in_workers(self._loader, master_config, [list(o) for o in batch], workers)
            if composed is not None:
                self._kept.update(zip((tuple(o) for o in batch), composed, strict=True))
                return
        for overrides in batch:
            self.keep(master_config, overrides)

    def load_sweep_config(self, master_config: DictConfig, sweep_overrides: list[str]) -> DictConfig:
        kept = self._kept.pop(tuple(sweep_overrides), None)
        if kept is not None:
            return kept
        return self._compose(master_config, sweep_overrides)

    def __getattr__(self, name):
        if name in ("_loader", "_kept"):      # not yet set (while unpickling): not the loader's
            raise AttributeError(name)
        return getattr(self._loader, name)

    def __getstate__(self):         # into another process: the loader only
        return {"_loader": self._loader, "_kept": {}}

    def __setstate__(self, state):
        self.__dict__.update(state)


MIN_CORES = 4      # on 2 shared cores the workers made composition slower (table2 at load 4: 0.8 -> 1.0-1.1 s)
_work: tuple = ()      # (loader, master configuration, batch) for the forked workers (set just before the fork)


def _compose_one(index: int) -> bytes:
    loader, master_config, batch = _work
    return pickle.dumps(loader.load_sweep_config(master_config, batch[index]))


def _compose_in_workers(loader, master_config: DictConfig, batch: list[list[str]], workers: int
                        ) -> list[DictConfig] | None:
    """The batch's configurations composed by `workers` forked processes, or None if any of that failed."""
    global _work
    _work = (loader, master_config, batch)
    try:
        # an executor, not a Pool: a worker killed mid-task (memory, a signal) raises BrokenProcessPool here,
        # where Pool.map would wait for the lost task for ever
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
            return [pickle.loads(blob) for blob in pool.map(_compose_one, range(len(batch)))]
    except Exception:  # noqa: BLE001 -- composed again here, where Hydra reports its own errors
        return None
    finally:
        _work = ()


class ComposedOnceSweeper(BasicSweeper):
    """BasicSweeper (same settings, same jobs) whose launcher reuses the configurations the check composed."""

    def setup(self, *, hydra_context: HydraContext, task_function, config: DictConfig) -> None:
        loader = _ComposedOnce(hydra_context.config_loader)
        super().setup(hydra_context=HydraContext(config_loader=loader, callbacks=hydra_context.callbacks),
                      task_function=task_function, config=config)

    def validate_batch_is_legal(self, batch: Sequence[Sequence[str]]) -> None:
        self.hydra_context.config_loader.keep_all(self.config, batch)
