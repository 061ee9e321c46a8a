"""Where batch jobs run: in this process, in a local process pool, or on Ray actors (local or a cluster).

All three share one small interface: `start` loads the model in every worker (and returns when they
are ready, so start-up and throughput are timed apart), `run` yields ``(task, result)`` pairs as they
finish with a bounded number in flight, `close` stops the workers. Why Ray for scale-out: it is an
existing engine that schedules actors onto a cluster's CPUs; each actor loads the model once and serves
many jobs, and the very same code runs against a local Ray or ``--ray HOST:PORT``.
"""

from __future__ import annotations

import os
import secrets
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait

from kinema.batch.ray_connect import init_bounded
from kinema.batch.spec import Task
from kinema.batch.worker import Worker, init_process, process_ping, process_run
from kinema.errors import KinemaError

#: Seconds `start` waits for every worker to load its model.
START_TIMEOUT = 900.0
RAY_MISSING = "--ray needs Ray: pip install 'kinema[batch]' (or pip install ray)"


class InlineExecutor:
    """One worker in this process (``--workers 1`` without Ray): no start-up of other processes."""

    workers = 1

    def __init__(self, model_spec: str, threads: int):
        self.model_spec, self.threads = model_spec, threads
        self.worker: Worker | None = None

    def start(self) -> None:
        self.worker = Worker(self.model_spec, self.threads)

    def run(self, tasks: Iterable[Task]) -> Iterator[tuple[Task, dict]]:
        assert self.worker is not None
        for task in tasks:
            yield task, self.worker.run(task.payload)

    def close(self) -> None:
        self.worker = None


class ProcessExecutor:
    """``workers`` processes (spawned: no fork of a process that holds torch threads), each loading the model once."""

    def __init__(self, model_spec: str, threads: int, workers: int):
        import multiprocessing

        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                        initializer=init_process, initargs=(model_spec, threads))

    def start(self) -> None:
        """Return once every process has loaded the model (pings until each pid has answered)."""
        seen: set[str] = set()
        deadline = time.monotonic() + START_TIMEOUT
        while len(seen) < self.workers:
            if time.monotonic() > deadline:
                raise KinemaError(f"only {len(seen)} of {self.workers} workers started within {START_TIMEOUT:g} s")
            seen.update(f.result() for f in [self.pool.submit(process_ping) for _ in range(self.workers)])
            time.sleep(0.05)

    def run(self, tasks: Iterable[Task]) -> Iterator[tuple[Task, dict]]:
        pending: dict[Future, Task] = {}
        source = iter(tasks)
        exhausted = False
        while pending or not exhausted:
            while not exhausted and len(pending) < 2 * self.workers:
                task = next(source, None)
                if task is None:
                    exhausted = True
                    break
                pending[self.pool.submit(process_run, task.payload)] = task
            if not pending:
                break
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                task = pending.pop(future)
                try:
                    yield task, future.result()
                except Exception as err:  # the process died (killed, out of memory): the pool is broken
                    raise KinemaError(f"a worker process died while running job {task.id!r} ({err})") from None

    def close(self) -> None:
        """Stop at once: queued jobs are dropped and running ones killed (a resumed batch redoes them)."""
        processes = list(getattr(self.pool, "_processes", {}).values())
        self.pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                p.terminate()


class RayExecutor:
    """``workers`` one-CPU Ray actors on a local Ray (``local``), the cluster Ray finds (``auto``) or ADDRESS."""

    def __init__(self, model_spec: str, threads: int, workers: int | None, address: str):
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no usage report leaves the machine unasked
        if address == "local":  # a private Ray: on loopback (Ray would pick the outward address), with a
            os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")  # one-off token instead of the
            if "RAY_AUTH_MODE" not in os.environ:  # ~/.ray/auth_token Ray would write (which later heads adopt)
                os.environ["RAY_AUTH_MODE"] = "token"
                os.environ.setdefault("RAY_AUTH_TOKEN", secrets.token_hex(32))
        try:
            import ray
        except ImportError:
            raise KinemaError(RAY_MISSING) from None
        self.ray = ray
        if address == "local":
            ray.init(address="local", include_dashboard=False, log_to_driver=False, num_cpus=workers)
        else:
            init_bounded(ray, address, log_to_driver=False)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = max(1, min(workers or cpus, cpus))
        actor = ray.remote(num_cpus=1)(Worker)
        self.actors = [actor.remote(model_spec, threads) for _ in range(self.workers)]

    def start(self) -> None:
        refs = [a.ping.remote() for a in self.actors]
        ready, _ = self.ray.wait(refs, num_returns=len(refs), timeout=START_TIMEOUT)
        if len(ready) < len(refs):
            raise KinemaError(f"only {len(ready)} of {len(refs)} Ray workers started within {START_TIMEOUT:g} s")
        self.ray.get(refs)

    def run(self, tasks: Iterable[Task]) -> Iterator[tuple[Task, dict]]:
        ray = self.ray
        idle = list(self.actors)
        pending: dict = {}
        source = iter(tasks)
        exhausted = False
        while pending or not exhausted:
            while idle and not exhausted:
                task = next(source, None)
                if task is None:
                    exhausted = True
                    break
                actor = idle.pop()
                pending[actor.run.remote(task.payload)] = (task, actor)
            if not pending:
                break
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            task, actor = pending.pop(ref)
            try:
                result = ray.get(ref)
            except ray.exceptions.RayError as err:  # the actor (or its node) died
                raise KinemaError(f"a Ray worker died while running job {task.id!r} ({type(err).__name__})") from None
            idle.append(actor)
            yield task, result

    def close(self) -> None:
        for a in self.actors:
            self.ray.kill(a)
        self.ray.shutdown()


def make_executor(model_spec: str, workers: int | None, ray_address: str | None, threads: int = 1):
    """The executor for ``--workers`` / ``--ray``: Ray when an address is given, else inline for one worker,
    else a process pool (``workers`` default: this machine's cores)."""
    from kinema.runtime import cpu_cores

    if ray_address:
        return RayExecutor(model_spec, threads, workers, ray_address)
    n = workers or cpu_cores()
    return InlineExecutor(model_spec, threads) if n == 1 else ProcessExecutor(model_spec, threads, n)
