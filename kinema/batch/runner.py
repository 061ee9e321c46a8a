"""The driver of `kinema batch`: read the jobs, skip the finished ones, run the rest, write files + manifest.

Why the driver writes everything: outputs are written atomically one by one and recorded in the manifest
right after (kinema.batch.manifest), in one process, so a batch killed at any instant can be rerun with
the same command and redoes only what is missing, never leaving a duplicate or a half-written file.
A job is finished when its last manifest record is ``ok``, its input hash (the job with its files' content)
and model hash match, and its files exist. Failed jobs are recorded and retried on the next run.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from kinema.atomic_files import atomic_write_bytes, make_output_folder
from kinema.batch.executors import make_executor
from kinema.batch.manifest import FolderLock, Manifest, remove_stale_temps
from kinema.batch.spec import Task, read_jobs
from kinema.errors import KinemaError
from kinema.input_files import check_input_file


@dataclass
class BatchSummary:
    """What one run did; ``startup_s`` is model loading in the workers, ``run_s`` the generation after it."""

    total: int = 0
    done: int = 0
    skipped: int = 0
    failed: int = 0
    workers: int = 0
    startup_s: float = 0.0
    run_s: float = 0.0
    errors: list[str] = field(default_factory=list)


def driver_model_sha(model_spec: str) -> str:
    """The fingerprint of the model the driver sees (workers report theirs; a mismatch fails the job)."""
    from kinema.generate import resolve_model_path
    from kinema.model.fingerprint import model_sha256
    from kinema.model.loading import find_checkpoint

    return model_sha256(find_checkpoint(resolve_model_path(model_spec)))


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _raw_id(text: str, line: int) -> str:
    """The ``id`` a line that failed to parse was meant to have: its own string ``id`` when it can be
    read, else the default every line without one gets (its line number, as kinema.batch.spec does)."""
    try:
        raw = json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        raw = None
    given = raw.get("id") if isinstance(raw, dict) else None
    return given if isinstance(given, str) and given else f"{line:06d}"


class ModelShas(dict):
    """Model spec -> the fingerprint the driver sees, computed once per spec (a bad spec: a KinemaError)."""

    def __missing__(self, spec: str) -> str:
        self[spec] = driver_model_sha(spec)
        return self[spec]


def _plan(jobs_path: Path, manifest: Manifest, out: Path, shas: ModelShas, default: str,
          summary: BatchSummary) -> list[Task]:
    """The tasks still to run; lines that cannot be parsed (or name a model that does not load) are
    recorded as failed right away."""
    finished = manifest.finished(out)
    todo = []
    for line, text, task in read_jobs(jobs_path):
        summary.total += 1
        if isinstance(task, KinemaError):
            manifest.append({"id": _raw_id(text, line), "line": line, "status": "failed", "input": text,
                             "error": str(task), "finished_at": _now()})
            summary.failed += 1
            summary.errors.append(f"line {line}: {task}")
            continue
        try:
            model_sha = shas[task.model or default]
        except KinemaError as err:
            manifest.append({"id": task.id, "line": line, "status": "failed", "input": text,
                             "error": f"model: {err}", "finished_at": _now()})
            summary.failed += 1
            summary.errors.append(f"line {line}: model: {err}")
            continue
        rec = finished.get(task.id)
        if rec and rec.get("input_sha256") == task.input_sha256 and rec.get("model_sha256") == model_sha:
            summary.skipped += 1
        else:
            todo.append(task)
    return todo


def _record(task: Task, result: dict, out: Path, model_spec: str, model_sha: str) -> dict:
    """Write a finished job's files (atomically) and return its manifest record (``model_spec``: the
    task's model, ``model_sha``: its fingerprint as the driver sees it)."""
    rec = {"id": task.id, "line": task.line, "input": task.raw, "input_sha256": task.input_sha256,
           "model": model_spec, "model_sha256": result.get("model_sha256"), "worker": result.get("worker")}
    if "error" not in result and result.get("model_sha256") != model_sha:
        result = result | {"error": f"the worker's model ({result.get('model_sha256', '?')[:12]}) is not the "
                                    f"driver's ({model_sha[:12]}): same --model on every node?"}
    if "error" in result:
        return rec | {"status": "failed", "error": result["error"], "finished_at": _now()}
    for name, data in zip(task.outputs, result["files"], strict=True):
        atomic_write_bytes(out / name, data)
    rep = result["report"]
    return rec | {"status": "ok", "outputs": task.outputs, "seconds": rep["seconds"], "frames": rep["frames"],
                  "steps": rep["steps"], "seed": rep["seed"], "residuals": rep["residuals"],
                  "warnings": rep["warnings"], "elapsed_s": round(result["elapsed_s"], 3), "finished_at": _now()}


def run_batch(jobs_path: str | Path, out: str | Path, *, model: str = "default", workers: int | None = None,
              ray: str | None = None, threads: int = 1, progress: bool = True) -> BatchSummary:
    """Run (or resume) a batch; see the module docstring. Raises KinemaError for unusable arguments."""
    from tqdm import tqdm

    jobs_path, out = Path(jobs_path), Path(out)
    check_input_file(jobs_path, "jobs file")
    make_output_folder(out)
    lock = FolderLock(out)
    manifest = Manifest(out)
    summary = BatchSummary()
    executor = None
    try:
        remove_stale_temps(out)
        shas = ModelShas()
        shas[model]  # the run's model must load before anything runs
        todo = _plan(jobs_path, manifest, out, shas, model, summary)
        if not todo:
            return summary
        t0 = time.perf_counter()
        executor = make_executor(model, workers, ray, threads)
        executor.start()
        summary.workers = executor.workers
        t1 = time.perf_counter()
        summary.startup_s = t1 - t0
        with tqdm(total=len(todo), unit="motion", desc="batch", disable=not progress, dynamic_ncols=True) as bar:
            for task, result in executor.run(todo):
                spec = task.model or model
                rec = _record(task, result, out, spec, shas[spec])
                manifest.append(rec)
                if rec["status"] == "ok":
                    summary.done += 1
                else:
                    summary.failed += 1
                    summary.errors.append(f"line {task.line} ({task.id}): {rec['error']}")
                    bar.set_postfix(failed=summary.failed)
                bar.update(1)
        summary.run_s = time.perf_counter() - t1
        return summary
    finally:
        if executor is not None:
            executor.close()
        manifest.close()
        lock.release()
