"""Generated motions and reports as JSON-ready values: BVH text, base64 npz, or arrays.

Why through kinema's own writers: BVH and npz bytes are exactly what ``motion.save`` (and so
``kinema generate``) writes, so a file from the API and one from the command line are the same file.
Reports are made JSON-safe here (tensors to lists, NaN and infinities to null), since the HTTP
answer must be strict JSON.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np

from kinema.motion.core import Motion
from kinema.pipeline.result import json_safe

#: File suffix per output format.
SUFFIX = {"bvh": ".bvh", "npz": ".npz", "glb": ".glb", "json": ".json", "csv": ".csv"}
#: Decimals kept in the JSON format (0.001 mm and 1e-6 of a quaternion: far below what matters).
JSON_DECIMALS = 6


def motion_arrays(motion: Motion) -> dict:
    """The ``json`` format: the npz format's arrays (docs/formats.md) as nested lists."""
    skel = motion.skeleton

    def rounded(t) -> list:
        return np.round(t.detach().cpu().numpy().astype(np.float64), JSON_DECIMALS).tolist()

    out = {
        "joint_names": list(skel.names),
        "parents": [int(p) for p in skel.parents],
        "fps": float(motion.fps),
        "offsets": rounded(skel.offsets),
        "root_translation": rounded(motion.root_translation),
        "local_quats": rounded(motion.local_rotations),
        "positions": rounded(motion.positions),
    }
    if motion.foot_contacts is not None:
        out["foot_contacts"] = rounded(motion.foot_contacts)
    return json_safe(out)


def encode_motion(motion: Motion, fmt: str, index: int, tmp: Path) -> dict:
    """One motion (or a robot's motion, kinema.robot.RobotMotion: csv or npz) as a ``MotionOut`` dict;
    ``tmp`` is a private scratch folder for the writers."""
    filename = f"motion_{index:02d}{SUFFIX[fmt]}"
    head = {"index": index, "format": fmt, "filename": filename, "frames": motion.num_frames, "fps": motion.fps}
    if fmt == "json":
        return head | {"encoding": "json", "data": motion_arrays(motion)}
    path = motion.save(Path(tmp) / filename)
    data = path.read_bytes()
    path.unlink()
    if fmt in ("bvh", "csv"):
        return head | {"encoding": "text", "data": data.decode("utf-8")}
    return head | {"encoding": "base64", "data": base64.b64encode(data).decode("ascii")}


MEDIA = {"text": "text/plain; charset=utf-8", "base64": "application/octet-stream", "json": "application/json"}


def file_payload(motion_out: dict) -> bytes:
    """A ``MotionOut`` dict's motion as the file's bytes (its media type: ``MEDIA[encoding]``)."""
    if motion_out["encoding"] == "text":
        return motion_out["data"].encode("utf-8")
    if motion_out["encoding"] == "base64":
        return base64.b64decode(motion_out["data"])
    return json.dumps(motion_out["data"], separators=(",", ":")).encode("utf-8")


def compact(response: dict) -> dict:
    """A GenerateResponse dict with each motion's ``data`` as file bytes (``payload``), for keeping jobs.

    Why: a finished job may wait in memory for minutes, and the bytes of a BVH/npz/JSON file are several
    times smaller than the same numbers as Python objects (a float in a list costs ~32 bytes)."""
    motions = [{k: v for k, v in m.items() if k != "data"} | {"payload": file_payload(m)} for m in response["motions"]]
    return response | {"motions": motions}


def expand(stored: dict) -> dict:
    """The GenerateResponse dict again from `compact`'s form."""
    motions = []
    for m in stored["motions"]:
        raw = m["payload"]
        data = {"text": lambda b: b.decode("utf-8"), "base64": lambda b: base64.b64encode(b).decode("ascii"),
                "json": json.loads}[m["encoding"]](raw)
        motions.append({k: v for k, v in m.items() if k != "payload"} | {"data": data})
    return stored | {"motions": motions}
