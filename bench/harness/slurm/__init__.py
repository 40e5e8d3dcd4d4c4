"""Sweeps on a SLURM cluster: the checked launcher (`launcher`, registered in hydra_plugins/); each job's memory
and time request comes from the memory model in bench.harness.resources."""
