"""Benchmark harness for near-field MIMO radar imaging on MAROON-format captures."""
