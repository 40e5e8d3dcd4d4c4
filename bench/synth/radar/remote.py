"""A Warp device's radar sums for other processes: the process that holds the device serves them.

CUDA does not survive a fork, and each process on the GPU would hold a context of its own (start-up, memory, the
kernels loaded again) and take turns on the device with the others; so worker processes (bench.synth.workers) send
the rows of each frame, split into blocks (`warp_sum.frame_of_blocks`'s arguments), over a local socket and receive
the frame. The sums run in the serving process exactly as they would in the worker, one frame per connection at a
time: the frames are the same (tests/bench/synth/test_synth_workers.py).
"""
from __future__ import annotations

import contextlib
import pickle
import secrets
import shutil
import socket
import tempfile
import threading
from multiprocessing import AuthenticationError
from multiprocessing.connection import Client, Connection, Listener
from pathlib import Path

from bench.synth.radar import warp_sum

ACCEPT_JOIN_S = 5.0        # how long closing waits for the accepting thread (a daemon: it cannot keep the process)


def _start_device() -> None:
    with contextlib.suppress(Exception):      # an error comes again, where it can be reported, with the first frame
        warp_sum.start()


class DeviceServer:
    """Serves `warp_sum.frame_of_blocks` to the processes that connect to `address` (path, key), one thread per
    connection, until closed; starts the device at once (its start overlaps the workers' first stages)."""

    def __init__(self):
        self._folder = Path(tempfile.mkdtemp(prefix="synth-device-"))
        self.address = (str(self._folder / "socket"), secrets.token_bytes(16))
        self._listener = Listener(self.address[0], "AF_UNIX", authkey=self.address[1])
        self._closing = False
        self._threads = [threading.Thread(target=_start_device, daemon=True),
                         threading.Thread(target=self._accept, daemon=True)]
        for thread in self._threads:
            thread.start()

    def __enter__(self) -> DeviceServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _accept(self) -> None:
        while True:
            try:
                connection = self._listener.accept()
            except (OSError, EOFError, AuthenticationError):   # closed, or a client that died in the handshake
                if self._closing:
                    return
                continue
            if self._closing:
                connection.close()
                return
            threading.Thread(target=self._serve, args=(connection,), daemon=True).start()

    @staticmethod
    def _serve(connection: Connection) -> None:
        with connection:
            while True:
                try:
                    arguments = connection.recv()
                except (EOFError, OSError):       # the worker has gone
                    return
                try:
                    reply = (True, warp_sum.frame_of_blocks(*arguments))
                except Exception as err:          # raised again in the worker that asked
                    reply = (False, err)
                try:
                    connection.send(reply)
                except (pickle.PicklingError, TypeError, AttributeError):   # an error that does not pickle
                    connection.send((False, RuntimeError(repr(reply[1]))))
                except OSError:                   # the worker has gone
                    return

    def close(self) -> None:
        """Stop accepting (the workers' connections end with them) and remove the socket."""
        self._closing = True
        with contextlib.suppress(OSError), socket.socket(socket.AF_UNIX) as wake:   # wakes the accepting thread
            wake.settimeout(ACCEPT_JOIN_S)          # (no handshake needed; a full backlog would block a connect)
            wake.connect(self.address[0])
        self._threads[1].join(timeout=ACCEPT_JOIN_S)
        self._listener.close()
        shutil.rmtree(self._folder, ignore_errors=True)


_lock = threading.Lock()


def connect(path: str, key: bytes) -> None:
    """Send this process's Warp sums (warp_sum.frame, its rows in blocks) to the DeviceServer at `path`."""
    connection = Client(path, "AF_UNIX", authkey=key)

    def frame(*arguments):
        with _lock:
            connection.send(arguments)
            ok, value = connection.recv()
        if not ok:
            raise value
        return value

    warp_sum.delegate(frame)
