"""Progress bars (bench.progress): drawn under a terminal, absent from captured output, and the commands' own lines
(print, logging) stay whole lines above the bar. Real commands run once on a pseudo-terminal and once piped."""
from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time

import pytest

BAR = re.compile(r"\d+/\d+ \[")               # tqdm's "n/total [elapsed..." part of a bar

SCRIPT = """
import logging
from bench.progress import each
logging.basicConfig(level=logging.INFO, format="log %(message)s")
for i in each(range(3), "demo steps", unit="item"):
    print(f"result {i}", flush=True)
    logging.getLogger("x").info("step %d", i)
print("done")
"""


def _on_pty(cmd: list[str], timeout_s: float = 300) -> tuple[int, str]:
    """Run `cmd` with stdout and stderr on a pseudo-terminal; its exit code and all it wrote (raw, with \\r)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 160, 0, 0))    # a new pty is 0 columns wide
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=slave, stderr=slave)
    os.close(slave)
    chunks, deadline = [], time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 1.0)
            if not ready:
                if proc.poll() is not None:
                    break
                continue
            try:
                data = os.read(master, 65536)
            except OSError:                   # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        return proc.wait(timeout=max(1.0, deadline - time.monotonic())), b"".join(chunks).decode(errors="replace")
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()


def _lines(raw: str) -> list[str]:
    """What a terminal shows per line: the text after the last carriage return, trailing blanks dropped."""
    return [line.split("\r")[-1].rstrip() for line in raw.replace("\r\n", "\n").split("\n")]


def test_bar_on_a_terminal_with_whole_lines_above_it():
    code, raw = _on_pty([sys.executable, "-c", SCRIPT])
    assert code == 0, raw
    assert "demo steps" in raw and BAR.search(raw), raw
    shown = _lines(raw)
    for i in range(3):                                  # printed and logged lines are not glued to a bar
        assert f"result {i}" in shown and f"log step {i}" in shown, shown
    assert "done" in shown


def test_no_bar_text_when_output_is_captured():
    result = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "result 0\nresult 1\nresult 2\ndone\n"
    assert result.stderr == "log step 0\nlog step 1\nlog step 2\n"       # logging only: no bar, no \r


def test_disabled_bar_draws_nothing_even_on_a_terminal():
    script = SCRIPT.replace('unit="item")', 'unit="item", enabled=False)')
    code, raw = _on_pty([sys.executable, "-c", script])
    assert code == 0 and "demo steps" not in raw and not BAR.search(raw), raw


def _sweep_job(root, out) -> list[str]:
    return [sys.executable, "-m", "bench", "dataset=maroon", f"dataset.root={root}", "method=mm2fsk", "freq=d10",
            "prior=realsense", "store.dir=null", f"hydra.run.dir={out}"]


def test_sweep_job_draws_a_frame_bar_on_a_terminal_only(synth_root, tmp_path):
    code, raw = _on_pty(_sweep_job(synth_root, tmp_path / "tty"))
    assert code == 0, raw
    assert re.search(r"MM-2FSK d10: .*\d/2 \[", raw), raw                 # the job's frames: 2 captures
    assert any(line.startswith("mm2fsk_d10_realsense: 2 captures") for line in _lines(raw)), raw
    piped = subprocess.run(_sweep_job(synth_root, tmp_path / "pipe"), capture_output=True, text=True, timeout=300)
    assert piped.returncode == 0, piped.stderr
    assert not BAR.search(piped.stdout + piped.stderr) and "\r" not in piped.stdout + piped.stderr


def test_perf_command_draws_its_bar_with_whole_result_lines(synth_root, tmp_path):
    code, raw = _on_pty([sys.executable, "-m", "bench.perf", "skips-gpu", "--root", str(synth_root), "--device", "cpu",
                         "--cases", "mm2fsk_d10", "--variants", "auto", "--repeat", "1", "--out", str(tmp_path)])
    assert code == 0, raw
    assert "cases:" in raw and BAR.search(raw), raw
    assert any(line.startswith("mm2fsk_d10    auto  median") for line in _lines(raw)), raw


CHILD = """
import os, sys
from bench.progress import each
print("tty", os.isatty(1), os.isatty(2), flush=True)
for i in each(range(2), "child steps", unit="item"):
    print(f"result {i}", flush=True)
print("error: data/x: broken", file=sys.stderr)
sys.exit(2)
"""


@pytest.mark.parametrize("terminal", [True, False], ids=["terminal", "pipe"])
def test_run_relayed_keeps_the_error_line_and_draws_bars_only_on_a_terminal(capfd, terminal):
    from bench.progress import run_relayed

    code, tail = run_relayed([sys.executable, "-c", CHILD], terminal=terminal)
    relayed = capfd.readouterr()
    assert code == 2 and tail[-1] == "error: data/x: broken", tail
    if terminal:           # one pseudo-terminal for both, relayed to our stdout: the child draws its bar
        assert "tty True True" in tail and "result 1" in tail
        assert "child steps" in relayed.out and BAR.search(relayed.out), relayed.out
    else:                  # stderr piped (no bar), stdout the child's own
        assert "child steps" not in relayed.out + relayed.err and relayed.out.split()[2] == "False"    # stderr


def test_a_heartbeat_says_how_far_a_loop_without_bar_is(capsys):
    """Off a terminal (pytest's stderr) a slow loop still reports: what runs, how far, about how long is left."""
    import time

    from bench import progress

    assert progress.how_far(2, 8, "frame", 40.0) == "2/8 frames done, 40 s, about 120 s left"
    assert progress.how_far(0, None, "frame", 3.0) == "0/? frames done, 3 s"
    beats = []
    with progress.Heartbeat(lambda: beats.append(1) or "MM-2FSK d10: 1/2 frames done", every_s=0.05):
        time.sleep(0.3)
    assert len(beats) >= 2 and "... MM-2FSK d10: 1/2 frames done\n" in capsys.readouterr().err


def test_before_its_first_step_a_loop_estimates_from_earlier_runs():
    from bench import progress

    assert progress.how_far(0, 8, "frame", 10.0, expected_s=5.0) == \
        "0/8 frames done, 10 s, about 30 s left (earlier runs)"
    assert progress.how_far(0, 8, "frame", 10.0) == "0/8 frames done, 10 s"
    assert progress.how_far(4, 8, "frame", 10.0, expected_s=5.0) == "4/8 frames done, 10 s, about 10 s left"
