"""The harness: `python -m bench` (the Hydra app, `app`), the pixel grids it evaluates on (`grids`), the run's
outputs (`results`), the content-keyed result store (`store`), sweep sizing (`sizing`) and SLURM (`slurm`,
`slurm_resources`), per-capture work shared by cells (`captures`), a row's parameters (`identity`), the end of
a sweep (`summary`), earlier runs' seconds per frame for estimates (`durations`) and the stage clock of
`python -m bench.perf experiment` (`stages`).
"""

from pathlib import Path

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"      # the Hydra configs (light: the demo imports it)
