"""`python -m bench ...`: the Hydra app (see bench/app.py)."""
from bench.app import main

main()
