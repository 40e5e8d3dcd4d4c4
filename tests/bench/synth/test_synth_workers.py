"""A catalogue built in worker processes (bench.synth.workers) is byte for byte the catalogue built in this process;
a Warp device's sums asked for by a worker are computed by the process that serves them (bench.synth.radar.remote),
frame for frame as in the worker; a failing part leaves no temp folder and no manifest entry."""
from __future__ import annotations

import dataclasses
import json
import multiprocessing
import socket
import threading
import time
import types
from multiprocessing.connection import Client

import numpy as np
import pytest

from bench.synth import SynthConfig, generate_catalogue, workers
from bench.synth.config import preset
from bench.synth.radar import leg_sum, remote, warp_sum

from devices import CUDA

OBJECTS = ["01_plate", "08_two_objects"]     # metal; metal and cardboard (multipath, transmission: realistic)
FAST = SynthConfig(frequency_points=16)


def _capture_files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in root.glob("*/30/**/*") if p.is_file()}


def _contents(root):
    return {k: v["content"] for k, v in json.loads((root / "synth_manifest.json").read_text())["captures"].items()}


def test_parts_built_in_worker_processes_are_the_files_built_in_this_process(tmp_path, monkeypatch):
    """The realistic preset (every effect, multipath) at 16 frequencies: worker processes against one thread."""
    config = dataclasses.replace(preset("realistic"), frequency_points=16)
    submitted = []

    class Counting(workers.ProcessPoolExecutor):
        def submit(self, *args, **kwargs):
            submitted.append(args[1:3])
            return super().submit(*args, **kwargs)

    monkeypatch.setattr(workers, "ProcessPoolExecutor", Counting)
    monkeypatch.setattr(workers, "capture_processes", lambda: True)
    monkeypatch.setattr(workers, "capture_workers", lambda: 3)
    built = generate_catalogue(tmp_path / "processes", [30], OBJECTS, config)
    assert len(submitted) == 2 * 3                           # every part of both captures went to a worker process
    monkeypatch.setattr(workers, "capture_processes", lambda: False)
    monkeypatch.setattr(workers, "capture_workers", lambda: 1)
    generate_catalogue(tmp_path / "thread", [30], OBJECTS, config)
    assert [r.status for r in built] == ["generated"] * 2
    files = _capture_files(tmp_path / "processes")
    assert len(files) > 20 and files == _capture_files(tmp_path / "thread")
    assert _contents(tmp_path / "processes") == _contents(tmp_path / "thread")
    assert not [p for p in (tmp_path / "processes").rglob(".*") if p.is_dir()]      # no temp folders left


def test_a_failing_part_leaves_no_temp_folder_and_no_manifest_entry(tmp_path, monkeypatch):
    from bench.synth import parts

    def broken(*args):
        raise RuntimeError("camera broke")

    monkeypatch.setattr(workers, "capture_processes", lambda: False)
    monkeypatch.setitem(parts.CAPTURE_PARTS, "camera", broken)
    with pytest.raises(RuntimeError, match="camera broke"):
        generate_catalogue(tmp_path, [30], OBJECTS, FAST)
    assert not [p for p in tmp_path.rglob(".*") if p.is_dir()]
    assert not list(tmp_path.glob("*/30"))
    assert json.loads((tmp_path / "synth_manifest.json").read_text())["captures"] == {}


def test_processes_only_where_a_worker_may_import_the_main_module_again(monkeypatch):
    monkeypatch.setattr(workers, "usable_cores", lambda: 16)
    for main, expected in [(types.SimpleNamespace(__spec__=types.SimpleNamespace(name="bench.synth.__main__"),
                                                  __file__="/x/bench/synth/__main__.py"), True),   # python -m
                           (types.SimpleNamespace(__spec__=None), True),                              # python -c
                           (types.SimpleNamespace(__spec__=None, __file__="/x/script.py"), False)]:   # a script
        monkeypatch.setitem(__import__("sys").modules, "__main__", main)
        assert workers.capture_processes() is expected
    monkeypatch.setattr(workers, "usable_cores", lambda: 2)
    assert workers.capture_processes() is False


def test_threads_where_the_machine_has_no_semaphores_for_worker_processes(monkeypatch):
    """No writable /dev/shm (some containers): a pool's locks cannot be made, so the parts are built in threads."""
    monkeypatch.setattr(workers, "usable_cores", lambda: 16)
    monkeypatch.setitem(__import__("sys").modules, "__main__", types.SimpleNamespace(__spec__=None))
    workers._semaphores_work.cache_clear()
    assert workers.capture_processes() is True

    def no_shm(self, *args, **kwargs):
        raise OSError(38, "Function not implemented")

    monkeypatch.setattr(type(multiprocessing.get_context(workers.START_METHOD)), "Lock", no_shm)
    workers._semaphores_work.cache_clear()
    try:
        assert workers.capture_processes() is False
    finally:
        workers._semaphores_work.cache_clear()


def _worker_frame(address, rows, positions, rx_m, tx_m, freqs_hz, device):
    remote.connect(*address)
    try:
        return warp_sum.frame(rows, positions, rx_m, tx_m, freqs_hz, device)
    except Exception as err:        # noqa: BLE001 - the test compares what reached the worker
        return err


def _rows(rng, n):
    points = rng.uniform([-0.05, -0.05, 0.28], [0.05, 0.05, 0.34], (n, 3))
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    amplitude = (rng.normal(size=n) + 1j * rng.normal(size=n)).astype(np.complex64)
    side = warp_sum.Side(points, normals, np.full(n, 0.3), amplitude)
    return warp_sum.Rows(side, warp_sum.Side(points, normals, np.full(n, 0.3)), 1.0, np.full(n, 0.5)), points


def _call_in_worker(address, *arguments):
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        return pool.apply(_worker_frame, (address, *arguments))


def test_a_worker_gets_the_frame_the_server_computes_and_its_errors(monkeypatch):
    """Without Warp: the server's frame function stands in; what the worker sends arrives intact, what it computes
    comes back intact, an error comes back as the error."""
    rng = np.random.default_rng(7)
    rows, points = _rows(rng, 5000)
    antennas = rng.uniform(-0.1, 0.1, (6, 3))
    seen = []

    def fake_frame(rows_, blocks, rx_m, tx_m, freqs_hz, device):
        if device == "bad":
            raise ValueError("no such device")
        seen.append((rows_, blocks))
        return np.full((len(rx_m), len(tx_m), len(freqs_hz)), rows_.rx.amplitude.sum(), np.complex64)

    monkeypatch.setattr(warp_sum, "frame_of_blocks", fake_frame)
    monkeypatch.setattr(warp_sum, "start", lambda: None)
    with remote.DeviceServer() as server:
        frame = _call_in_worker(server.address, rows, points, antennas[:2], antennas[2:], np.arange(5.0), "x")
        error = _call_in_worker(server.address, rows, points, antennas[:2], antennas[2:], np.arange(5.0), "bad")
    assert frame.shape == (2, 4, 5) and np.all(frame == rows.rx.amplitude.sum())
    blocks = leg_sum.compact_blocks(points, leg_sum.BLOCK_ROWS)               # made in the worker
    assert len(blocks) > 1 and len(seen[0][1]) == len(blocks) and all(map(np.array_equal, seen[0][1], blocks))
    np.testing.assert_array_equal(seen[0][0].tx.lobe_rad, rows.tx.lobe_rad)
    np.testing.assert_array_equal(seen[0][0].rx.point_m, points)
    assert isinstance(error, ValueError) and "no such device" in str(error)


def test_a_client_that_dies_in_the_handshake_leaves_the_server_serving(monkeypatch):
    """A worker killed while connecting (a bare connect, then gone) must not end the accepting thread: the next
    worker is served, and closing returns at once."""
    monkeypatch.setattr(warp_sum, "start", lambda: None)
    monkeypatch.setattr(warp_sum, "frame_of_blocks", lambda *a: np.ones((1, 1, 1), np.complex64))
    with remote.DeviceServer() as server:
        for _ in range(2):
            with socket.socket(socket.AF_UNIX) as dying:
                dying.connect(server.address[0])
        replies = []

        def ask():
            with Client(server.address[0], "AF_UNIX", authkey=server.address[1]) as client:
                client.send(())
                replies.append(client.recv())

        asking = threading.Thread(target=ask, daemon=True)      # a dead accepting thread would leave it waiting
        asking.start()
        asking.join(timeout=10)
        assert replies and replies[0][0] is True
        started = time.monotonic()
    assert time.monotonic() - started < remote.ACCEPT_JOIN_S and not server._threads[1].is_alive()


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_a_worker_s_warp_frame_is_the_frame_summed_in_this_process(device):
    """The worker never touches the device (it may not: CUDA does not survive a fork); the frame it receives is the
    one this process sums, bit for bit."""
    pytest.importorskip("warp")
    from bench.maroon.antennas import load_antenna_array

    rng = np.random.default_rng(int(np.random.SeedSequence().entropy % 2**32))
    rows, points = _rows(rng, 3000)
    antennas = load_antenna_array(all_elements=True)
    freqs = np.linspace(72e9, 82e9, 16)
    here = warp_sum.frame(rows, points, antennas.rx_m, antennas.tx_m, freqs, device)
    with remote.DeviceServer() as server:
        there = _call_in_worker(server.address, rows, points, antennas.rx_m, antennas.tx_m, freqs, device)
    assert np.abs(here).max() > 0
    np.testing.assert_array_equal(there, here)


def test_a_capture_s_parts_built_in_any_order_are_the_same_files(tmp_path):
    """The parts share nothing but their inputs (each builds the scene and draws its own seeded stream), so the
    order the workers happen to take them in does not matter."""
    from bench.synth import parts

    config = dataclasses.replace(preset("realistic"), frequency_points=16)
    for name, order in (("forward", list(parts.CAPTURE_PARTS)), ("backward", list(parts.CAPTURE_PARTS)[::-1])):
        (tmp_path / name).mkdir()
        for part in order:
            parts.build_part(tmp_path / name, part, "08_two_objects", 30, config)
    forward = {p.relative_to(tmp_path / "forward"): p.read_bytes() for p in (tmp_path / "forward").rglob("*")
               if p.is_file()}
    assert len(forward) > 10
    assert forward == {p.relative_to(tmp_path / "backward"): p.read_bytes()
                       for p in (tmp_path / "backward").rglob("*") if p.is_file()}
