"""Console entry points (pyproject `[project.scripts]`): `mm2fsk-bench` is `python -m bench` (the Hydra app, with
Hydra's shell completion: `eval "$(mm2fsk-bench -sc install=bash)"`), `mm2fsk-demo`, `mm2fsk-report`,
`mm2fsk-tables`, `mm2fsk-synth`, `mm2fsk-inspect`, `mm2fsk-stress` and `mm2fsk-sweep` are the `python -m bench.<x>`
commands. The `python -m` forms stay; both run the same code."""
import runpy


def _module(name: str) -> None:
    runpy.run_module(name, run_name="__main__", alter_sys=False)


def bench() -> None:
    _module("bench")


def demo() -> None:
    _module("bench.demo")


def report() -> None:
    _module("bench.report")


def tables() -> None:
    _module("bench.report.tables")


def synth() -> None:
    _module("bench.synth")


def inspect() -> None:
    _module("bench.maroon.inspect_capture")


def stress() -> None:
    _module("bench.stress")


def sweep() -> None:
    _module("bench.report.merge")
