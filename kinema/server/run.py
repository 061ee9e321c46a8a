"""One generation request, from validated body to JSON answer; runs on a worker thread.

Why this shape: everything that needs the model but no computing (model/rig lookup, the model's step
limit) is checked in `prepare`, on the request, so a bad request costs no queue slot; `execute` does
the work. Safety: the prompt always reaches kinema inside a timeline list (kinema reads a *string*
ending in ``.json`` as a timeline file), constraints always as parsed JSON (never a path), and inline
BVH text is written to a private temporary folder whose paths alone reach kinema's BVH reader.
"""

from __future__ import annotations

import base64
import binascii
import copy
import tempfile
from dataclasses import dataclass
from pathlib import Path

from kinema.errors import KinemaError
from kinema.pipeline.request import GenerationRequest
from kinema.retarget import load_character
from kinema.server.encode import encode_motion, json_safe
from kinema.server.errors import RequestError, from_kinema
from kinema.server.models import ModelRegistry, ServedModel
from kinema.server.schemas import InlineRig


@dataclass
class Prepared:
    """A request checked against the server's models, ready for a worker."""

    served: ServedModel
    request: GenerationRequest
    rig: InlineRig | str | None


def prepare(req, registry: ModelRegistry, max_steps: int) -> Prepared:
    """Resolve the model and check what needs it; raises `RequestError` (a 422) otherwise. It reads an
    inline character (a 909 KB BVH takes seconds), so the routes run it off the event loop."""
    served = registry.resolve(req.model, req.rig, humanoid=_is_humanoid(req.rig))
    limit = served.max_steps(max_steps)
    if req.steps is not None and req.steps > limit:
        raise RequestError.at(["body", "steps"], f"at most {limit} for model {served.name!r}")
    try:
        request = req.to_request()
    except KinemaError as err:
        raise from_kinema(err) from None
    return Prepared(served, request, req.rig)


def _is_humanoid(rig) -> bool:
    """Whether an inline character is a humanoid (kinema.retarget.detect); False for anything else."""
    if not isinstance(rig, InlineRig):
        return False
    with tempfile.TemporaryDirectory(prefix="kinema-serve-") as tmp:
        try:
            return load_character(_inline_rig(rig, Path(tmp))).is_humanoid
        except KinemaError as err:
            raise from_kinema(err, hide=tmp) from None


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


def _inline_rig(rig, folder: Path):
    """The request's rig for kinema: a rig id as it is, an inline character as a file in ``folder``."""
    if not isinstance(rig, InlineRig):
        return rig
    path = folder / f"character.{rig.format}"
    if rig.format == "bvh":
        path.write_text(rig.data, encoding="utf-8")
        return str(path)
    try:
        path.write_bytes(base64.b64decode(rig.data, validate=True))
    except (binascii.Error, ValueError):
        raise RequestError.at(["body", "rig", "data"], "not valid base64 (a .glb file, base64-encoded)") from None
    return str(path)


def execute(prep: Prepared) -> dict:
    """Generate and encode; returns a ``GenerateResponse`` dict. KinemaErrors become `RequestError`."""
    model, fmt = prep.served.model, prep.request.format or "bvh"
    with tempfile.TemporaryDirectory(prefix="kinema-serve-") as tmp:
        folder = Path(tmp)
        try:
            request = prep.request.replace(constraints=_inline_bvh(prep.request.constraints, folder),
                                           rig=_inline_rig(prep.rig, folder))
            result = model.generate(request)
            outputs = result.robot_motions or list(result)
            motions = [encode_motion(m, fmt, i, folder) for i, m in enumerate(outputs)]
        except KinemaError as err:
            raise from_kinema(err, hide=tmp) from None
    report = json_safe(result.report.to_dict())
    report["warnings"] = [str(w) for w in report["warnings"]]
    rig = prep.rig if isinstance(prep.rig, str) else prep.served.rig
    return {"model": prep.served.name, "rig": rig, "format": fmt, "motions": motions, "report": report}
