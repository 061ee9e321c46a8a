"""The jobs file of `kinema batch`: one JSON object per line, each one motion (or ``samples`` motions).

Why resolve files here, on the driver: a job may name a constraints or timeline file (relative to the
jobs file); the driver reads it and passes plain JSON to the workers, so a worker on another machine
needs no copy of those files, and the job's input hash covers their content (edit a constraints file and
its jobs run again on resume). BVH files named inside constraints are made absolute and are read by
the worker: on a cluster they must be on a shared path. A prompt always travels as a one-segment
timeline, since kinema reads a prompt string ending in ``.json`` as a timeline file name.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, StrictBool, ValidationError

from kinema.errors import KinemaError
from kinema.server.schemas import MAX_SEED, Finite, PositiveFinite, Segment, Strict

Format = Literal["bvh", "bvh.gz", "npz"]
DEFAULT_SECONDS = 5.0


class BatchJob(Strict):
    """One line of a jobs file (unknown keys are errors)."""

    id: Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")] | None = None
    prompt: str | None = None
    seconds: PositiveFinite | None = None
    timeline: list[Segment] | str | None = None
    constraints: list[dict[str, Any]] | dict[str, Any] | str | None = None
    constraints_fps: PositiveFinite | None = None
    samples: Annotated[int, Field(ge=1, le=64)] = 1
    steps: Annotated[int, Field(ge=1)] | None = None
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = 0
    guidance: tuple[Annotated[float, Field(ge=0, allow_inf_nan=False)],
                    Annotated[float, Field(ge=0, allow_inf_nan=False)]] | None = None
    heading: Finite = 0.0
    postprocess: StrictBool = True
    format: Format = "bvh"


@dataclass
class Task:
    """A parsed, resolved job: what the driver sends a worker and what the manifest records."""

    id: str
    line: int
    raw: dict
    payload: dict  # JSON for the worker: timeline, constraints, settings, format, outputs
    input_sha256: str

    @property
    def outputs(self) -> list[str]:
        return self.payload["outputs"]


def output_names(job_id: str, fmt: str, samples: int) -> list[str]:
    """``ID.EXT`` for one sample, ``ID_00.EXT``, ``ID_01.EXT``, ... for several."""
    if samples == 1:
        return [f"{job_id}.{fmt}"]
    return [f"{job_id}_{i:02d}.{fmt}" for i in range(samples)]


def _read_json(path: Path, what: str):
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise KinemaError(f"{what} {path}: cannot read it ({err})") from None
    except (json.JSONDecodeError, RecursionError) as err:
        raise KinemaError(f"{what} {path}: not valid JSON ({err})") from None


def _absolute_bvh(constraints, folder: Path):
    """Constraint objects read from a file in ``folder``: relative ``bvh`` paths made absolute, looked up
    like kinema does (the file's folder, then the current directory)."""
    items = constraints.get("constraints") if isinstance(constraints, dict) else constraints
    for obj in items if isinstance(items, list) else []:
        if isinstance(obj, dict) and isinstance(obj.get("bvh"), str) and not Path(obj["bvh"]).is_absolute():
            for base in (folder, Path.cwd()):
                if (base / obj["bvh"]).is_file():
                    obj["bvh"] = str((base / obj["bvh"]).resolve())
                    break
    return constraints


def _resolve(job: BatchJob, base: Path) -> dict:
    """The worker payload of ``job`` (files read, prompt as a timeline); raises KinemaError."""
    if (job.prompt is None) == (job.timeline is None):
        raise KinemaError("give exactly one of 'prompt' and 'timeline'")
    if job.timeline is not None and job.seconds is not None:
        raise KinemaError("'seconds' is for a prompt; timeline segments carry their own seconds")
    if isinstance(job.timeline, str):
        timeline = _read_json(base / job.timeline, "timeline")
    elif job.timeline is not None:
        timeline = [s.model_dump() for s in job.timeline]
    else:
        timeline = [{"prompt": job.prompt, "seconds": job.seconds or DEFAULT_SECONDS}]
    constraints = job.constraints
    if isinstance(constraints, str):
        path = base / constraints
        constraints = _absolute_bvh(_read_json(path, "constraints"), path.parent)
    elif constraints is not None:
        constraints = _absolute_bvh(constraints, base)
    settings = {"constraints_fps": job.constraints_fps, "samples": job.samples, "steps": job.steps,
                "seed": job.seed, "guidance": job.guidance, "heading": job.heading, "postprocess": job.postprocess}
    return {"timeline": timeline, "constraints": constraints, "settings": settings, "format": job.format}


def parse_line(text: str, line: int, base: Path) -> Task:
    """One jobs-file line -> Task; raises KinemaError naming the problem (the batch records it)."""
    try:
        raw = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as err:
        raise KinemaError(f"not valid JSON ({err})") from None
    if not isinstance(raw, dict):
        raise KinemaError(f"expected a JSON object, got {type(raw).__name__}")
    try:
        job = BatchJob.model_validate(raw)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "line"
        raise KinemaError(f"field {where}: {first['msg']}") from None
    payload = _resolve(job, base)
    job_id = job.id or f"{line:06d}"
    payload["outputs"] = output_names(job_id, job.format, job.samples)
    digest = hashlib.sha256(json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    return Task(job_id, line, raw, payload, digest)


def read_jobs(path: str | Path) -> list[tuple[int, str, Task | KinemaError]]:
    """Every non-blank line of a jobs file: ``(line number, text, Task or the error that line has)``.

    A second job with an id already used is an error of its own line (its outputs would overwrite)."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise KinemaError(f"{path}: cannot read the jobs file ({err})") from None
    out: list[tuple[int, str, Task | KinemaError]] = []
    seen: dict[str, int] = {}
    for n, text in enumerate(lines, 1):
        if not text.strip():
            continue
        try:
            task: Task | KinemaError = parse_line(text, n, path.parent)
        except KinemaError as err:
            task = err
        if isinstance(task, Task):
            if task.id in seen:
                task = KinemaError(f"id {task.id!r} is also used on line {seen[task.id]}")
            else:
                seen[task.id] = n
        out.append((n, text, task))
    return out
