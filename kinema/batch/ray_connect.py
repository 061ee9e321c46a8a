"""Joining a Ray cluster within a bounded time (issue 36: ``--ray 127.0.0.1:1`` retried for ever).

``ray.init(address=...)`` keeps retrying an address where no Ray listens. Before it runs, a
``HOST:PORT`` or ``ray://HOST:PORT`` address is probed with a plain TCP connection
(`PROBE_TIMEOUT` seconds): nothing listening is a one-line error at once. Then a short-lived child
process tries ``ray.init`` on the address and is given `CONNECT_TIMEOUT` seconds (something that
accepts connections but is no Ray head, or ``auto`` finding a dead cluster); past that it is killed
and the batch stops with a one-line error. Only an address the child joined is joined in this
process. (A thread would not do: a ``ray.init`` given up on keeps running inside Ray's C++ core,
and the process aborts with ``std::bad_alloc`` when it exits.) ``KINEMA_RAY_TIMEOUT`` (seconds)
overrides `CONNECT_TIMEOUT`.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys

from kinema.errors import KinemaError
from kinema.runtime import positive_from_env

PROBE_TIMEOUT = 5.0
CONNECT_TIMEOUT = 60.0
TIMEOUT_ENV = "KINEMA_RAY_TIMEOUT"


def host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of a ``HOST:PORT`` / ``ray://HOST:PORT`` address; None for ``auto``/``local``."""
    rest = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = rest.rpartition(":")
    if not sep or not host:
        return None
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise KinemaError(f"--ray {address}: expected HOST:PORT with a port 1-65535, 'local' or 'auto'")
    return host.strip("[]"), int(port)


def probe(address: str, timeout: float = PROBE_TIMEOUT) -> None:
    """A one-line error when nothing accepts TCP connections at ``address`` within ``timeout`` seconds."""
    target = host_port(address)
    if target is None:
        return
    try:
        with socket.create_connection(target, timeout=timeout):
            pass
    except OSError as err:
        reason = "timed out" if isinstance(err, TimeoutError) else (err.strerror or type(err).__name__)
        raise KinemaError(f"--ray {address}: cannot reach a Ray head there ({reason}); start one with "
                          "`ray start --head` or use --ray local") from None


def connect_timeout() -> float:
    return positive_from_env(TIMEOUT_ENV, CONNECT_TIMEOUT)


#: what the child process runs: join, leave, exit 0
JOIN_SCRIPT = "import sys, ray; ray.init(address=sys.argv[1], log_to_driver=False); ray.shutdown()"


def check_joinable(address: str, limit: float) -> None:
    """A one-line error unless a child process joins the cluster at ``address`` within ``limit`` seconds."""
    child = subprocess.Popen([sys.executable, "-c", JOIN_SCRIPT, address], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _, err = child.communicate(timeout=limit)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)
        child.communicate()
        raise KinemaError(f"--ray {address}: no Ray cluster answered within {limit:g} s (is a Ray head running "
                          f"there? {TIMEOUT_ENV} sets the wait)") from None
    if child.returncode != 0:
        lines = [line.strip() for line in err.splitlines() if line.strip()]
        reason = lines[-1] if lines else f"exit status {child.returncode}"
        raise KinemaError(f"--ray {address}: cannot join the Ray cluster ({reason})")


def init_bounded(ray, address: str, **kwargs) -> None:
    """``ray.init(address=address, **kwargs)`` once a child process has joined there within `connect_timeout`."""
    probe(address)
    check_joinable(address, connect_timeout())
    ray.init(address=address, **kwargs)
