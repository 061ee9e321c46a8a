"""Bounds on inputs whose cost grows without limit, checked before any heavy work (issue 36).

The request's own bounds (seconds, samples, steps, ...) live in kinema.pipeline.request
(`RequestBounds`); this module holds the ones that belong to an input file rather than a request field:

- ``MAX_RIG_JOINTS`` (256): the largest rig an any-rig model generates for. Its attention runs over
  every joint of every frame, so time grows with the square of the joint count (creatures model,
  2-s motion, 20 DDIM steps, 2 CPU cores: 48 joints 1.2 s, 128 joints 6.7 s, 256 joints 13 s,
  512 joints 63 s; a 5000-joint chain ran over 3 minutes with no output). The training rigs have 2-48
  joints, so 256 leaves room for rigs five times larger than any it learnt from. Override it for a
  process with the environment variable ``KINEMA_MAX_RIG_JOINTS`` or per call with ``max_joints=``.

- ``MAX_RIG_REACH`` (1000 m): the longest root-to-joint chain of a glTF rig in metres, after its armature
  scale. A character a kilometre across is a wrong export unit or scale (a GLB scaled by 1e6 moved its pelvis
  at 4.3e6 m/s), as a BVH length beyond `kinema.io.bvh_data.MAX_METRES` is.
- ``MAX_JSON_BYTES`` (16 MiB): the largest JSON, JSON-lines or CSV input file (mappings, rig overrides,
  timelines, constraints, stream scripts, jobs files); the largest shipped one is a few hundred KB.
- ``MAX_ASSET_BYTES`` (1 GiB): the largest rig or motion file (BVH, glTF/GLB and its buffer files). Both
  are read through kinema.input_files, which stops after ``max + 1`` bytes (``/dev/zero`` included).

Reading and inspecting a rig has no joint limit (the tree walks are iterative; ``kinema inspect`` on a
5000-joint chain takes a few seconds).
"""

from __future__ import annotations

from kinema.errors import KinemaError
from kinema.runtime import positive_from_env

MAX_RIG_JOINTS = 256
RIG_JOINTS_ENV = "KINEMA_MAX_RIG_JOINTS"
MAX_RIG_REACH = 1000.0
MAX_JSON_BYTES = 16 * 1024 * 1024
MAX_ASSET_BYTES = 1024 * 1024 * 1024


def max_rig_joints() -> int:
    """`MAX_RIG_JOINTS`, or the positive integer in ``$KINEMA_MAX_RIG_JOINTS``."""
    return int(positive_from_env(RIG_JOINTS_ENV, MAX_RIG_JOINTS, integer=True))


def check_rig_joints(num_joints: int, where: str, max_joints: int | None = None) -> None:
    """A one-line error when a rig of ``num_joints`` is too large to generate for in reasonable time."""
    limit = max_rig_joints() if max_joints is None else max_joints
    if num_joints > limit:
        raise KinemaError(f"{where}: {num_joints} joints; an any-rig model generates for at most {limit} "
                          f"(its time grows with the square of the joint count; set {RIG_JOINTS_ENV} to allow more)")
