"""Server settings: every limit of `kinema serve` in one frozen dataclass, plus the bind/API-key rules.

Why one place: the limits shape the request schema (kinema.server.schemas puts them into the OpenAPI
document), the worker pool, the job store and the body-size middleware, and docs/server.md lists them;
keeping them together means a new limit is added once and shows up everywhere.
"""

from __future__ import annotations

import ipaddress
import math
from dataclasses import dataclass, field
from pathlib import Path

from kinema.errors import KinemaError

#: Shortest API key accepted from ``--api-key-file`` (a guessable key is no protection).
MIN_KEY_CHARS = 16


@dataclass(frozen=True)
class ServerLimits:
    """What one request may ask for and how much work the server keeps in memory at once.

    ``max_seconds`` caps the whole output (a timeline's segments added up); ``max_samples`` and
    ``max_steps`` cap ``samples`` and ``steps`` (steps also by each model's trained diffusion length);
    ``max_body_bytes`` caps a request body (413 above it); ``workers`` generation threads share the
    loaded models and at most ``queue`` more requests wait (429 with Retry-After past that);
    ``timeout_s`` bounds how long ``POST /v1/generate`` waits for its result (504 after it: use jobs);
    ``max_jobs`` finished jobs are kept at most ``job_ttl_s`` seconds each (the oldest go first);
    ``read_timeout_s`` is the longest wait for the next part of a request body (408 after it).
    """

    max_seconds: float = 30.0
    max_samples: int = 4
    max_steps: int = 100
    max_body_bytes: int = 2 * 1024 * 1024
    max_prompt_chars: int = 1000
    max_segments: int = 32
    max_constraints: int = 256
    workers: int = 1
    queue: int = 8
    timeout_s: float = 120.0
    max_jobs: int = 64
    job_ttl_s: float = 900.0
    read_timeout_s: float = 10.0

    def __post_init__(self) -> None:
        for name in ("max_samples", "max_steps", "max_body_bytes", "max_prompt_chars", "max_segments",
                     "max_constraints", "workers", "max_jobs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise KinemaError(f"--{name.replace('_', '-')} must be a positive integer, got {value!r}")
        if isinstance(self.queue, bool) or not isinstance(self.queue, int) or self.queue < 0:
            raise KinemaError(f"--queue must be an integer >= 0, got {self.queue!r}")
        for name in ("max_seconds", "timeout_s", "job_ttl_s", "read_timeout_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise KinemaError(f"--{name.replace('_', '-')} must be a positive number, got {value!r}")

    def as_dict(self) -> dict:
        """The limits as JSON (``GET /v1/models`` and ``/healthz`` report them)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class ServerConfig:
    """Where the server listens, who may call it, and its limits."""

    host: str = "127.0.0.1"
    port: int = 8000
    api_keys: tuple[str, ...] = ()
    cors_origins: tuple[str, ...] = ()
    limits: ServerLimits = field(default_factory=ServerLimits)

    def __post_init__(self) -> None:
        if not is_loopback(self.host) and not self.api_keys:
            raise KinemaError(f"--host {self.host} is not a loopback address: anyone who can reach it could use the "
                              "server, so give --api-key-file FILE (or bind to 127.0.0.1)")


def is_loopback(host: str) -> bool:
    """Whether ``host`` only listens on this machine: ``localhost``, 127.0.0.0/8 or ``::1``."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False  # a host name other than localhost may resolve anywhere


def read_api_keys(path: str | Path) -> tuple[str, ...]:
    """API keys from a file, one per line (blank lines and ``#`` comments ignored).

    Each key must be at least `MIN_KEY_CHARS` characters of printable ASCII without spaces, so that a
    key can travel in an HTTP header as it is. A file without keys is an error (it would lock every
    client out, or, worse, be mistaken for "no key needed")."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise KinemaError(f"--api-key-file {path}: cannot read it ({err})") from None
    keys = []
    for n, line in enumerate(text.splitlines(), 1):
        key = line.strip()
        if not key or key.startswith("#"):
            continue
        if len(key) < MIN_KEY_CHARS or not key.isascii() or not key.isprintable() or " " in key:
            raise KinemaError(f"--api-key-file {path}:{n}: a key must be at least {MIN_KEY_CHARS} printable ASCII "
                              "characters without spaces (e.g. `python -c 'import secrets; "
                              "print(secrets.token_urlsafe(32))'`)")
        keys.append(key)
    if not keys:
        raise KinemaError(f"--api-key-file {path}: holds no key")
    return tuple(keys)
