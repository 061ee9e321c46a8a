"""A bounded pool of generation threads: ``workers`` run, at most ``queue`` more wait, the rest are refused.

Why threads, not processes: one loaded `KinemaModel` is shared by every thread (it is thread-safe and
torch releases the GIL inside its kernels), so N workers cost one copy of the weights. Why a hard bound:
a full server must say 429 at once (with a Retry-After estimated from recent work) instead of queueing
without limit; each admitted task holds its slot until its thread has *finished*, even when the client
gave up (a running torch call cannot be interrupted), so memory and CPU stay bounded under any load.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor


class PoolFull(Exception):
    """Every worker is busy and the queue is full; ``retry_after`` is a suggested wait in seconds."""

    def __init__(self, retry_after: int):
        self.retry_after = retry_after
        super().__init__(f"server busy; retry in {retry_after} s")


class WorkerPool:
    """``submit`` runs a function on one of ``workers`` threads, or raises `PoolFull`."""

    def __init__(self, workers: int, queue: int):
        self.workers = workers
        self.capacity = workers + queue
        self._executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="kinema-generate")
        self._lock = threading.Lock()
        self._pending = 0
        self._durations: deque[float] = deque(maxlen=32)

    @property
    def pending(self) -> int:
        """Tasks admitted and not finished (running or waiting)."""
        with self._lock:
            return self._pending

    def submit(self, fn: Callable, *args) -> Future:
        """Admit ``fn(*args)`` or raise `PoolFull`; the slot is freed when the task ends (or is cancelled)."""
        with self._lock:
            if self._pending >= self.capacity:
                raise PoolFull(self._retry_after_locked())
            self._pending += 1
        try:
            future = self._executor.submit(self._timed, fn, args)
        except BaseException:
            self._release(None)
            raise
        future.add_done_callback(self._release)
        return future

    def _timed(self, fn: Callable, args: tuple):
        t0 = time.perf_counter()
        try:
            return fn(*args)
        finally:
            with self._lock:
                self._durations.append(time.perf_counter() - t0)

    def _release(self, _future) -> None:
        with self._lock:
            self._pending -= 1

    def retry_after(self) -> int:
        """Seconds until a slot is likely free (see `_retry_after_locked`)."""
        with self._lock:
            return self._retry_after_locked()

    def _retry_after_locked(self) -> int:
        """Seconds until a slot is likely free: the mean recent task time times the waiting rounds."""
        mean = sum(self._durations) / len(self._durations) if self._durations else 1.0
        rounds = max(1, self._pending - self.workers + 1) / self.workers
        return max(1, min(3600, math.ceil(mean * rounds)))

    def shutdown(self) -> None:
        """Stop taking work; queued tasks are cancelled, running ones finish."""
        self._executor.shutdown(wait=False, cancel_futures=True)
