"""Jobs for long work: ``POST /v1/jobs`` queues a generation and answers at once with an id to poll.

Why bounded with expiry: results live in memory, so the store keeps at most ``max_jobs`` jobs; a
finished job expires ``ttl`` seconds after it finished, and when the store is full the oldest finished
job is dropped first. Unfinished jobs are never dropped; there are at most as many as the worker
pool admits (its queue bound), so a store full of unfinished jobs answers 429 like the pool does.
"""

from __future__ import annotations

import secrets
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field


@dataclass
class Job:
    """One job; ``result`` is its GenerateResponse in kinema.server.encode.compact form once ``done``."""

    id: str
    created: float = field(default_factory=time.time)
    status: str = "queued"
    started: float | None = None
    finished: float | None = None
    result: dict | None = None
    error: list[dict] | str | None = None


class StoreFull(Exception):
    """No room for another job: every kept job is still queued or running."""


class JobStore:
    """Thread-safe id -> Job map with a size bound and expiry of finished jobs."""

    def __init__(self, max_jobs: int, ttl: float):
        self.max_jobs = max_jobs
        self.ttl = ttl
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        with self._lock:
            self._expire_locked(time.time())
            return len(self._jobs)

    def create(self) -> Job:
        """A new queued job, making room by dropping expired then oldest finished jobs; or `StoreFull`."""
        with self._lock:
            now = time.time()
            self._expire_locked(now)
            if len(self._jobs) >= self.max_jobs:
                oldest = next((j for j in self._jobs.values() if j.finished is not None), None)
                if oldest is None:
                    raise StoreFull(f"{self.max_jobs} jobs are queued or running; try again later")
                del self._jobs[oldest.id]
            job = Job(id=secrets.token_hex(16))
            self._jobs[job.id] = job
            return job

    def get(self, job_id: str) -> Job | None:
        with self._lock:
            self._expire_locked(time.time())
            return self._jobs.get(job_id)

    def discard(self, job_id: str) -> None:
        with self._lock:
            self._jobs.pop(job_id, None)

    def update(self, job: Job, **changes) -> None:
        """Change a job's fields under the lock (workers and request handlers see whole states)."""
        with self._lock:
            for key, value in changes.items():
                setattr(job, key, value)

    def expires(self, job: Job) -> float | None:
        return None if job.finished is None else job.finished + self.ttl

    def _expire_locked(self, now: float) -> None:
        for job_id in [j.id for j in self._jobs.values() if j.finished is not None and j.finished + self.ttl <= now]:
            del self._jobs[job_id]
