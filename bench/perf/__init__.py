"""Benchmarks, one command with subcommands: `python -m bench.perf NAME [options]` (`python -m bench.perf` lists
them). Each subcommand is one module here with a `main(argv)`; `common` holds what they share (the output
folder, CSV rows, percentiles, shared options). Figures are printed beside a plain implementation timed in the
same run; benchmarks are never tests.
"""
