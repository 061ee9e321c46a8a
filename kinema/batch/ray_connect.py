"""Joining a Ray cluster within a bounded time (issue 36: ``--ray 127.0.0.1:1`` retried for ever).

``ray.init(address=...)`` keeps retrying an address where no Ray listens. Before it runs, a
``HOST:PORT`` or ``ray://HOST:PORT`` address is probed with a plain TCP connection
(`PROBE_TIMEOUT` seconds): nothing listening is a one-line error at once. Then ``ray.init`` itself
runs in a daemon thread that is given `CONNECT_TIMEOUT` seconds (something that accepts connections
but is no Ray head, or ``auto`` finding a dead cluster); past that the batch stops with a one-line
error. ``KINEMA_RAY_TIMEOUT`` (seconds) overrides `CONNECT_TIMEOUT`.
"""

from __future__ import annotations

import socket
import threading

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


def init_bounded(ray, address: str, **kwargs) -> None:
    """``ray.init(address=address, **kwargs)`` that gives up after `connect_timeout` seconds."""
    probe(address)
    limit = connect_timeout()
    outcome: dict = {}

    def connect() -> None:
        try:
            ray.init(address=address, **kwargs)
            outcome["ok"] = True
        except Exception as err:  # reported in the caller's thread
            outcome["error"] = err

    thread = threading.Thread(target=connect, name="kinema-ray-init", daemon=True)
    thread.start()
    thread.join(limit)
    if thread.is_alive():
        raise KinemaError(f"--ray {address}: no Ray cluster answered within {limit:g} s (is a Ray head running "
                          f"there? {TIMEOUT_ENV} sets the wait)")
    if "error" in outcome:
        err = outcome["error"]
        raise KinemaError(f"--ray {address}: cannot join the Ray cluster ({type(err).__name__}: "
                          f"{str(err).splitlines()[0] if str(err) else ''})") from None
