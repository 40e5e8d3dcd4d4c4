"""`python -m bench.report ROOT`: the HTML report of a sweep (bench.report.html)."""
from bench import cli
from bench.report.html import main

cli.run_guarded(main)
