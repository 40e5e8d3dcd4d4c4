"""Numerical stability and robustness stress suite: `python -m bench.stress [--quick] [--out results/stress]`.

One module per experiment, each returning plain rows (list of dicts) that `__main__` writes as CSV and plots:
`precision` (float32 fast paths vs the float64 reference), `wrapping` (prior offsets through the unambiguous
range), `noise` (MM-2FSK depth std vs the Cramer-Rao bound), `prior_degradation` (RealSense noise, holes and
extrinsic error), `hostile` (degenerate and malicious input). Scenes are analytic and in memory (`scenes`).
"""
