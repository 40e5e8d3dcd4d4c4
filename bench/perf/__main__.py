"""`python -m bench.perf NAME [options]`: run one benchmark (a module of this package); no NAME lists them."""
import importlib
import sys

from bench import cli

#: subcommand -> (module of bench.perf, what it measures)
COMMANDS = {
    "correlate": ("correlate", "the correlation kernels against a plain direct sum, then whole frames"),
    "frames": ("frames", "whole fresh frames of every method through methods.reconstruct"),
    "stream": ("stream", "a frame sequence read and reconstructed as a camera delivers it"),
    "sweep": ("sweep", "each cell of a sweep on one capture: methods against the harness around them"),
    "overhead": ("overhead", "what a sweep pays outside the methods, by stage"),
    "experiment": ("experiment", "a whole experiment as a user runs it: wall time against methods + metrics, by stage"),
    "memory": ("memory", "peak memory of sweep cells against the SLURM memory model"),
    "fill": ("fill", "prior hole fills (scanline, delaunay) in runtime against error"),
    "skips": ("skips.cpu", "every skip off and on per catalogue object (CPU)"),
    "skips-gpu": ("skips.gpu", "the skips on fresh frames on a Warp device"),
    "skips-reference": ("skips.reference", "the public reference kernels' full computation for the skips"),
    "formation": ("formation", "the column-separable BP and BP_max's search on the device, runtime against error"),
    "synth": ("synth", "synthetic capture generation by stage, radar echo from frequency nodes and direct"),
}


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = [f"  {name:<{width}}  {what}" for name, (_, what) in COMMANDS.items()]
    return "usage: python -m bench.perf NAME [options]  (NAME --help for its options)\n" + "\n".join(lines)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        raise cli.UserError("python -m bench.perf", f"unknown benchmark {name!r}; choose one of {', '.join(COMMANDS)}")
    module = importlib.import_module(f"bench.perf.{COMMANDS[name][0]}")
    sys.argv[0] = f"python -m bench.perf {name}"
    return module.main(rest)


if __name__ == "__main__":     # importable: the tests read COMMANDS
    cli.run_guarded(lambda: main(sys.argv[1:]))
