"""The linters of CI: ruff with the project's rule sets (pyproject.toml [tool.ruff]: pycodestyle, pyflakes, isort,
bugbear, pyupgrade) finds nothing, and import-linter's contracts (pyproject.toml [tool.importlinter]: the layers
of docs/DESIGN.md, no cycles) hold - and fail, naming the chain, when an import against them is planted."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")
PACKAGES = ("bench", "methods", "metrics")


def test_ruff_finds_nothing():
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "bench", "methods", "metrics", "tests", "examples",
                             "hydra_plugins"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def _lint_imports(root: Path) -> subprocess.CompletedProcess:
    # PYTHONPATH=root: the packages under `root` are the ones analysed (not the installed ones)
    return subprocess.run([str(LINT_IMPORTS), "--config", str(root / "pyproject.toml"), "--no-cache"], cwd=root,
                          capture_output=True, text=True, timeout=300, env={"PYTHONPATH": str(root), "PATH": ""})


def test_the_import_contracts_hold():
    result = _lint_imports(REPO)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


def _planted_copy(tmp_path: Path, module: str, line: str) -> Path:
    for package in PACKAGES:
        shutil.copytree(REPO / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__", "*.dat"))
    shutil.copy(REPO / "pyproject.toml", tmp_path)
    path = tmp_path / module
    path.write_text(path.read_text() + f"\n{line}\n")
    return tmp_path


def test_a_planted_import_against_the_layers_fails_with_its_chain(tmp_path):
    root = _planted_copy(tmp_path, "methods/domain/errors.py", "import metrics.masks  # planted")
    result = _lint_imports(root)
    assert result.returncode != 0
    assert "BROKEN" in result.stdout and "methods.domain.errors -> metrics.masks" in result.stdout


def test_a_planted_cycle_fails(tmp_path):
    root = _planted_copy(tmp_path, "methods/ops/filtering.py", "import methods.skips.roi  # planted")
    result = _lint_imports(root)
    assert result.returncode != 0
    assert "methods.ops.filtering -> methods.skips.roi" in result.stdout
