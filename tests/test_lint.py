"""The linter of CI: ruff with the project's rules (pyproject.toml [tool.ruff]: syntax errors and pyflakes, i.e.
undefined names, unused imports and variables, redefinitions) finds nothing in the sources, tests and examples."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    pytest.importorskip("ruff", reason="ruff is a test extra (pip install -e .[test]); CI installs it")
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "bench", "methods", "metrics", "tests", "examples"],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
