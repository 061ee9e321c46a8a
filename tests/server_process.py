"""Servers started by tests: a free local port for them, and stopping a `kinema serve` started in its own
process group (tests/test_server.py, tests/test_stream_server.py)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess


def free_port() -> int:
    """A local TCP port nothing listens on now (the OS picks it)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop_server(proc: subprocess.Popen) -> None:
    """SIGTERM the server's process group, SIGKILL it when it has not ended within 15 s."""
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(15)
