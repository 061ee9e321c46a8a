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

from pydantic import Field, ValidationError

from kinema.errors import KinemaError
from kinema.input_files import read_json_bounded, read_text_bounded
from kinema.pipeline.request_json import Segment, request_model, to_request

Format = Literal["bvh", "bvh.gz", "npz", "glb", "csv"]
DEFAULT_SECONDS = 5.0

#: One line of a jobs file (unknown keys are errors): every `GenerationRequest` field
#: (kinema.pipeline.request_json), with files named relative to the jobs file where a request takes a file
#: (timeline, constraints, rig), plus the line's ``id`` and ``model`` (default: the run's ``--model``).
BatchJob = request_model(
    "BatchJob",
    overrides={
        "prompt": (str | None, Field(None, description='what the character does ("" = no text)')),
        "timeline": list[Segment] | str,
        "constraints": list[dict[str, Any]] | dict[str, Any] | str,
        "objectives": list[dict[str, Any]],
        "rig": Annotated[str, Field(max_length=1000, description="a GLB/BVH file (relative to the jobs file) or a "
                                                                 "training rig id")],
        "format": (Format, Field("bvh", description="output format: bvh, bvh.gz, npz or glb; csv or npz with a robot")),
        "robot": Annotated[str, Field(max_length=1000,
                                      description="'g1', 'h1' or an MJCF file (relative to the jobs file)")],
        "robot_mapping": dict[str, Any] | str,
    },
    extra={"id": (Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")] | None, None),
           "model": (Annotated[str, Field(max_length=1000)] | None, None)},
)


@dataclass
class Task:
    """A parsed, resolved job: what the driver sends a worker and what the manifest records."""

    id: str
    line: int
    raw: dict
    payload: dict  # JSON for the worker: the request (files read), the model, the outputs
    input_sha256: str
    model: str | None = None  # the line's model spec (None: the run's --model)

    @property
    def outputs(self) -> list[str]:
        return self.payload["outputs"]


def output_names(job_id: str, fmt: str, samples: int) -> list[str]:
    """``ID.EXT`` for one sample, ``ID_00.EXT``, ``ID_01.EXT``, ... for several."""
    if samples == 1:
        return [f"{job_id}.{fmt}"]
    return [f"{job_id}_{i:02d}.{fmt}" for i in range(samples)]


def _read_json(path: Path, what: str):
    return read_json_bounded(path, f"{what} file")


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


def _local_file(name: str | None, base: Path) -> tuple[str | None, str | None]:
    """A rig or robot that names a file (relative to the jobs file, then the current directory) as an
    absolute path and the file's sha256 (so editing the character runs its jobs again); an id as it is."""
    if name is None:
        return None, None
    for folder in (base, Path.cwd()):
        path = folder / name
        if path.is_file():
            return str(path.resolve()), hashlib.sha256(path.read_bytes()).hexdigest()
    return name, None


def _resolve(job, base: Path) -> dict:
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
    rig, rig_sha = _local_file(job.rig, base)
    robot, robot_sha = _local_file(job.robot, base)
    mapping = job.robot_mapping
    if isinstance(mapping, str):
        mapping = _read_json(base / mapping, "robot mapping")
    request = to_request(job, prompt="", seconds=None, timeline=timeline, constraints=constraints, rig=rig,
                         robot=robot, robot_mapping=mapping)
    return {"request": request.to_json(), "model": job.model, "rig_sha256": rig_sha, "robot_sha256": robot_sha}


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
    return Task(job_id, line, raw, payload, digest, job.model)


def read_jobs(path: str | Path) -> list[tuple[int, str, Task | KinemaError]]:
    """Every non-blank line of a jobs file: ``(line number, text, Task or the error that line has)``.

    A second job with an id already used is an error of its own line (its outputs would overwrite)."""
    path = Path(path)
    lines = read_text_bounded(path, "jobs file").splitlines()
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
