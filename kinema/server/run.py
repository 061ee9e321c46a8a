"""One generation request, from validated body to JSON answer; runs on a worker thread.

Why this shape: everything that needs the model but no computing (model/rig lookup, the model's step
limit) is checked in `prepare`, on the request, so a bad request costs no queue slot; `execute` does
the work. Safety: the prompt always reaches kinema inside a timeline list (kinema reads a *string*
ending in ``.json`` as a timeline file), constraints always as parsed JSON (never a path), and inline
BVH text is written to a private temporary folder whose paths alone reach kinema's BVH reader.
"""

from __future__ import annotations

import copy
import tempfile
from dataclasses import dataclass
from pathlib import Path

from kinema.errors import KinemaError
from kinema.server.encode import encode_motion, json_safe
from kinema.server.errors import RequestError, from_kinema
from kinema.server.models import ModelRegistry, ServedModel


@dataclass
class Prepared:
    """A request checked against the server's models, ready for a worker."""

    served: ServedModel
    timeline: list[dict]
    constraints: list[dict] | None
    settings: dict
    fmt: str


def prepare(req, registry: ModelRegistry, max_steps: int) -> Prepared:
    """Resolve the model and check what needs it; raises `RequestError` (a 422) otherwise."""
    served = registry.resolve(req.model, req.rig)
    limit = served.max_steps(max_steps)
    if req.steps is not None and req.steps > limit:
        raise RequestError.at(["body", "steps"], f"at most {limit} for model {served.name!r}")
    constraints = [c.to_kinema() for c in req.constraints] if req.constraints else None
    settings = {"constraints_fps": req.constraints_fps, "samples": req.samples, "steps": req.steps, "seed": req.seed,
                "guidance": None if req.guidance is None else tuple(req.guidance), "heading": req.heading,
                "postprocess": req.postprocess}
    return Prepared(served, req.timeline_json(), constraints, settings, req.format)


def _inline_bvh(constraints, folder: Path):
    """A copy of ``constraints`` whose inline ``bvh`` texts are files in ``folder`` (absolute paths)."""
    if constraints is None:
        return None
    out = copy.deepcopy(constraints)
    for i, obj in enumerate(out):
        if "bvh" in obj:
            path = folder / f"inline_{i:03d}.bvh"
            path.write_text(obj["bvh"], encoding="utf-8")
            obj["bvh"] = str(path.resolve())
    return out


def execute(prep: Prepared) -> dict:
    """Generate and encode; returns a ``GenerateResponse`` dict. KinemaErrors become `RequestError`."""
    model = prep.served.model
    with tempfile.TemporaryDirectory(prefix="kinema-serve-") as tmp:
        folder = Path(tmp)
        try:
            result = model.generate(prep.timeline, constraints=_inline_bvh(prep.constraints, folder),
                                    progress=False, **prep.settings)
            motions = [encode_motion(m, prep.fmt, i, folder) for i, m in enumerate(result)]
        except KinemaError as err:
            raise from_kinema(err) from None
    rep = result.report
    report = {"seconds": rep.seconds, "segments": rep.segments, "frames": rep.frames, "steps": rep.steps,
              "guidance": list(rep.guidance), "seed": rep.seed, "residuals": json_safe(rep.residuals),
              "warnings": [str(w) for w in rep.warnings], "prompts": json_safe(rep.prompts)}
    return {"model": prep.served.name, "rig": prep.served.rig, "format": prep.fmt, "motions": motions,
            "report": report}
