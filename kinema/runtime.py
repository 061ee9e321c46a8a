"""Process-wide runtime settings: how many CPU threads torch may use, and where caches live.

Caches (text embeddings) go to a user-level folder, not the current one (:func:`user_cache_dir`):
``$KINEMA_CACHE_DIR``, else ``$XDG_CACHE_HOME/kinema``, else ``~/.cache/kinema``.

Why this exists: kinema's tensors are small (a 2.9 M-parameter denoiser, batches of a few hundred frames),
so torch's intra-op parallelism gains little on a quiet machine and loses a lot on a busy one: when other
processes hold the cores, every parallel region waits for its slowest thread (measured on the 2-core
development machine: 2 threads are 1.4x faster than 1 when it is quiet, several times slower under load;
see docs/speed.md). One function, :func:`configure_threads`, decides the thread count for every command
(``kinema generate --threads``, ``kinema train --threads``, ``kinema bench``), from the argument, else the
``KINEMA_THREADS`` environment variable, else :func:`default_threads`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from kinema.errors import KinemaError

#: Environment variable read when no thread count is given explicitly.
ENV_VAR = "KINEMA_THREADS"
#: Environment variable naming kinema's cache folder (default: the XDG user cache).
CACHE_ENV_VAR = "KINEMA_CACHE_DIR"

#: Idle cores (cores minus the 1-minute load average) needed before a second thread is used.
MIN_FREE_FOR_TWO = 1.75


def user_cache_dir(*parts: str) -> Path:
    """kinema's user cache folder (not created here), or a sub-folder of it: ``$KINEMA_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/kinema``, else ``~/.cache/kinema`` (the XDG base-directory convention)."""
    own = os.environ.get(CACHE_ENV_VAR, "").strip()
    if own:
        base = Path(own).expanduser()
    else:
        xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
        base = (Path(xdg).expanduser() if xdg and Path(xdg).is_absolute() else Path.home() / ".cache") / "kinema"
    return base.joinpath(*parts)


def text_cache_dir() -> Path:
    """Where the CLI keeps text embeddings between processes (``user_cache_dir("text")``)."""
    return user_cache_dir("text")


def positive_from_env(name: str, default: float, integer: bool = False) -> float:
    """The positive number (an integer when ``integer``) in environment variable ``name``, ``default``
    when it is unset or blank; anything else is a one-line `KinemaError` naming the variable."""
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = int(text) if integer else float(text)
    except ValueError:
        value = -1
    if not (value > 0 and math.isfinite(value)):
        raise KinemaError(f"{name}: expected a positive {'integer' if integer else 'number'}, got {text!r}")
    return value


def _check_count(value, source: str) -> int:
    """``value`` as a positive int, or a KinemaError that names ``source`` (an option or variable)."""
    if isinstance(value, bool):
        raise KinemaError(f"{source} must be a positive integer, got {value!r}")
    if isinstance(value, str):
        text = value.strip()
        try:
            value = int(text)
        except ValueError:
            raise KinemaError(f"{source} must be a positive integer, got {text!r}") from None
    if not isinstance(value, int) or value < 1:
        raise KinemaError(f"{source} must be a positive integer, got {value!r}")
    return value


def cpu_cores() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one, else ``os.cpu_count``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def load_average() -> float | None:
    """The 1-minute load average, or None where the OS has none (Windows)."""
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None


def default_threads(cores: int | None = None, load: float | None = None, cap: int | None = 2) -> int:
    """The thread count used when neither an argument nor ``KINEMA_THREADS`` gives one.

    The idle cores (``cores`` minus the 1-minute load average), rounded, at most ``cap`` (None: no cap),
    and 1 unless at least ``MIN_FREE_FOR_TWO`` cores are idle. Why: on the 2-core development machine two
    threads are 1.4x faster than one when it is idle, but 3-16x slower as soon as other processes want
    the cores (every parallel region waits for its slowest thread), and a second thread only pays when
    it surely gets a core of its own (docs/speed.md has the measurements). ``cap = 2`` suits generation
    (the small model's matrices are small); training passes ``cap=None`` to keep using every idle core.
    ``cores`` and ``load`` default to this machine's; a machine without a load average counts as idle.
    """
    cores = cpu_cores() if cores is None else cores
    load = load_average() if load is None else load
    free = cores - (load or 0.0)
    if free < MIN_FREE_FOR_TWO:
        return 1
    n = min(cores, int(free + 0.25))
    return max(1, n if cap is None else min(cap, n))


def _set_interop(n: int) -> None:
    """Match torch's inter-op pool to ``n`` when that is still allowed.

    kinema runs no inter-op parallel work, so the pool only costs idle threads. torch refuses to resize
    it once any parallel work has run (or once it was set), raising RuntimeError; then it stays as it is.
    """
    import torch

    if torch.get_num_interop_threads() == n:
        return
    try:
        torch.set_num_interop_threads(n)
    except RuntimeError:
        pass


def configure_threads(n: int | None = None, *, cap: int | None = 2) -> int:
    """Set torch's intra-op thread count and return it.

    ``n`` when given (a positive int; anything else raises KinemaError naming ``--threads``), else the
    ``KINEMA_THREADS`` environment variable (a bad value raises KinemaError naming the variable), else
    :func:`default_threads` with ``cap``. The inter-op pool is resized to match when torch still allows it.
    """
    import torch

    if n is not None:
        n = _check_count(n, "--threads")
    else:
        env = os.environ.get(ENV_VAR)
        if env is not None and env.strip():
            n = _check_count(env, f"the environment variable {ENV_VAR}")
        else:
            n = default_threads(cap=cap)
    torch.set_num_threads(n)
    _set_interop(n)
    return n


def resolve_device(name: str | None = None):
    """The torch device for ``--device NAME``: ``cpu`` (default, also for None), ``cuda`` or ``cuda:N``,
    ``auto`` (CUDA when available, else CPU).

    Why a check here: torch accepts ``cuda`` on a CPU-only build and fails only at the first tensor, deep
    inside training; this fails at once with a message naming the option.
    """
    import torch

    name = "cpu" if name is None else str(name).strip().lower()
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    try:
        device = torch.device(name)
    except RuntimeError:
        raise KinemaError(f"--device: unknown device {name!r} (cpu, cuda, cuda:N or auto)") from None
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise KinemaError(f"--device {name}: this torch build or machine has no CUDA device")
        if device.index is not None and device.index >= torch.cuda.device_count():
            raise KinemaError(f"--device {name}: only {torch.cuda.device_count()} CUDA device(s)")
    elif device.type != "cpu":
        raise KinemaError(f"--device: {name!r} is not supported (cpu, cuda, cuda:N or auto)")
    return device
