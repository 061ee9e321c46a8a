"""Stopping a `kinema serve` started by a test in its own process group (tests/test_server.py,
tests/test_stream_server.py)."""

from __future__ import annotations

import os
import signal
import subprocess


def stop_server(proc: subprocess.Popen) -> None:
    """SIGTERM the server's process group, SIGKILL it when it has not ended within 15 s."""
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(15)
