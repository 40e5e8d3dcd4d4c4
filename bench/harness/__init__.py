"""The harness: `python -m bench` (the Hydra app, `app`), the pixel grids it evaluates on (`grids`), the run's
outputs (`results`), the content-keyed result store (`store`), sweep sizing (`sizing`) and SLURM (`slurm`,
`slurm_resources`).
"""
