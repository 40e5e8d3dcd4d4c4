"""`python -m bench` ends without the interpreter's teardown (bench.__main__.QuickExit), with its exit code, after
every exit handler."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

# a module-level object whose finalizer runs only in the interpreter's teardown of __main__'s globals
SCRIPT = """
import runpy, sys
class TornDown:
    def __del__(self):
        print("torn down", flush=True)
kept = TornDown()
sys.argv = ["bench", *sys.argv[1:]]
runpy.run_module("bench", run_name="__main__")
"""


@pytest.mark.parametrize("args, code", [(["--help"], 0), (["--no-such-flag"], 2)], ids=["help", "user error"])
def test_the_process_ends_with_its_code_after_the_exit_handlers_without_teardown(tmp_path, args, code):
    stages_file = tmp_path / "stages.json"
    result = subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True, text=True, timeout=120,
                            env={**os.environ, "BENCH_STAGES_FILE": str(stages_file)})
    assert result.returncode == code, result.stderr
    assert "torn down" not in result.stdout                        # no teardown of the modules' objects
    assert "process_s" in json.loads(stages_file.read_text())     # an exit handler registered later still ran
    if code:
        assert result.stderr.startswith("error: ") and len(result.stderr.splitlines()) == 1
    else:
        assert "mm2fsk-bench" in result.stdout                     # stdout flushed before the end
