#!/usr/bin/env bash
# One entry point that sets itself up: `bash run.sh demo` (main job on the embedded synthetic dataset) or
# `bash run.sh test` (the test suite). Set-up is idempotent: system package, .venv, the package (re-installed only
# when pyproject.toml changes). Extra arguments go to the job (e.g. `bash run.sh test -k reader`).
set -euo pipefail
cd "$(dirname "$0")"

# requirements open3d: pyproject's open3d-cpu line; requirements rest: the others (with the test extra) and
# open3d-cpu's own minus those its import never loads (run.sh's set-up, below)
requirements() {
  .venv/bin/python - "$1" <<'PY'
import importlib.metadata, re, sys, tomllib
project = tomllib.load(open("pyproject.toml", "rb"))["project"]
ours = project["dependencies"] + project["optional-dependencies"]["test"]
name = lambda line: re.match(r"[A-Za-z0-9._-]+", line)[0].lower()
if sys.argv[1] == "open3d":
    print(*[line for line in ours if name(line) == "open3d-cpu"], sep="\n")
    sys.exit()
try:
    theirs = importlib.metadata.requires("open3d-cpu") or []
except importlib.metadata.PackageNotFoundError:  # another platform: the full open3d with all it declares
    theirs = []
unused = {"ipywidgets", "nbformat", "configargparse"}
print(*[line for line in ours if name(line) != "open3d-cpu"],
      *[line for line in theirs if "extra ==" not in line and name(line) not in unused], sep="\n")
PY
}

need_libusb() { ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; }

setup() {
  if need_libusb; then  # `import open3d` needs Debian's libusb-1.0-0
    echo "[setup] installing system package libusb-1.0-0"
    sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
    $sudo_cmd apt-get install -y -q libusb-1.0-0 >/dev/null 2>&1 \
      || { $sudo_cmd apt-get update -q >/dev/null && $sudo_cmd apt-get install -y -q libusb-1.0-0 >/dev/null; }
  fi
  if [ ! -x .venv/bin/python ]; then
    py=""
    for cand in python3.11 python3.12 python3.13 python3; do
      if command -v "$cand" >/dev/null && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
        py=$cand; break
      fi
    done
    [ -n "$py" ] || { echo "error: Python >= 3.11 is required" >&2; exit 1; }
    echo "[setup] creating .venv with $($py --version)"
    "$py" -m venv .venv
  fi
  stamp=".venv/.installed-$(cat pyproject.toml run.sh | sha256sum | cut -c1-16)"
  if [ ! -f "$stamp" ]; then
    echo "[setup] installing the package and its dependencies into .venv (first run: a few minutes, 4 steps)"
    echo "[setup] 1/4 pip itself"
    .venv/bin/python -m pip install -q --upgrade pip
    # open3d-cpu declares ipywidgets, nbformat and ConfigArgParse (Jupyter widgets, notebook files, a CLI helper:
    # with IPython and jedi ~70 MB) that `import open3d` never loads. Install it without its declared
    # dependencies, then ours plus those of its own that its import does load (dash, plotly, flask: its
    # visualization package imports its plotly viewer), then this package without resolving again. A plain
    # `pip install .` still works and brings them all.
    echo "[setup] 2/4 open3d-cpu (mesh reading and ray casting)"
    requirements open3d > .venv/requirements-open3d.txt
    .venv/bin/python -m pip install -q --no-deps -r .venv/requirements-open3d.txt
    echo "[setup] 3/4 numpy, scipy, warp, hydra, pandas, matplotlib and the rest (the longest step)"
    requirements rest > .venv/requirements-rest.txt
    .venv/bin/python -m pip install -q --no-warn-conflicts -r .venv/requirements-rest.txt
    echo "[setup] 4/4 this package (editable)"
    # compat: the project folder on sys.path, so that Hydra's plugin scan finds hydra_plugins/mm2fsk_bench (its
    # sweeper and launchers) from any working directory; the default editable finder hides it from that scan
    .venv/bin/python -m pip install -q --no-deps -e . --config-settings editable_mode=compat
    rm -f .venv/.installed-*; touch "$stamp"
    echo "[setup] done"
  fi
}

job=${1:-}
[ $# -gt 0 ] && shift
case "$job" in
  demo)
    setup
    .venv/bin/python -m bench.demo "$@"
    ;;
  test)
    setup
    .venv/bin/python -m pytest -q "$@"
    ;;
  setup)
    setup
    ;;
  *)
    if [ -z "$job" ]; then problem="no job given"; else problem="unknown job '$job'"; fi
    echo "error: bash run.sh: $problem (usage: bash run.sh demo|test|setup [args...])" >&2
    exit 2
    ;;
esac
