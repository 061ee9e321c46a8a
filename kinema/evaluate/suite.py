"""The evaluation test suite (Kimodo paper Sec. 6.1): text-only and constrained cases from test clips.

``build_suite(data_dir, split, num_cases, seed)`` draws a deterministic list of cases (plain dicts,
JSON-ready) from a dataset build; ``save_suite`` / ``load_suite`` keep it on disk so that different
models, or the same model over time, are scored on identical cases. Case kinds (docs/evaluation.md):

- ``text``: text-only generation from a clip's first caption, ``seconds`` = clip length clamped to
  [3, 9] s;
- constrained kinds, targets taken from a 3-9 s crop of a ground-truth clip: ``fullbody_sparse``
  (K random full-body keyframes), ``inbetween`` (blocks of keyframes at the start and/or end),
  ``end_effector`` (sparse hand/foot positions and/or rotations, with the GT smoothed root),
  ``waypoints`` (sparse 2D root, sometimes with heading), ``path`` (dense 2D root over an interval) and
  ``mixed`` (two of those). Each has a text flag (prompt or ``""``), and about a quarter are
  *perturbed*: the GT crop is turned by a random heading and shifted by up to +-2 m before the targets
  are extracted.

The ground truth of a case is the crop ``features_to_motion(features[start:start+frames])``, moved so
that its first smoothed root is over the origin facing ``heading`` (0 = +Z) and shifted by ``offset``
(see :func:`case_ground_truth`). Constraints are kinema JSON (docs/constraints.md) in the world
coordinates of that motion, with ``frame_indices`` at the dataset fps.
"""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_to_axis_angle
from kinema.kinematics import forward_kinematics
from kinema.motion.contacts import ContactThresholds, foot_contacts
from kinema.motion.core import Motion
from kinema.representation.kimodo_features import features_to_motion, motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.transform import canonicalize_start, translate_features

SUITE_FORMAT, SUITE_VERSION = "kinema-eval-suite", 1
CONSTRAINED_KINDS = ("fullbody_sparse", "inbetween", "end_effector", "waypoints", "path", "mixed")
CASE_KINDS = ("text", *CONSTRAINED_KINDS, "timeline")  # timeline cases: kinema.evaluate.timeline
MIN_SECONDS, MAX_SECONDS = 3.0, 9.0
MAX_KEYFRAMES = 10  # sparse keyframes per constraint: 1..10, biased towards few (weights 1/K)
INBETWEEN_BLOCK = (1, 5)  # frames per in-between block
PERTURB_FRACTION, PERTURB_METRES = 0.25, 2.0
EFFECTORS = ("left-hand", "right-hand", "left-foot", "right-foot")
_MIXABLE = ("fullbody_sparse", "inbetween", "end_effector", "waypoints", "path")


# ----------------------------------------------------------------------------- ground truth
def _open_dataset(data_dir, split: str):
    from kinema.data.dataset import MotionDataset

    return MotionDataset(data_dir, split)


def ground_truth_motion(features: torch.Tensor, dataset, heading: float = 0.0, offset=(0.0, 0.0)) -> Motion:
    """GT motion of a feature crop (T, D): first smoothed root over ``offset`` (x, z) facing ``heading``
    radians; foot contacts re-derived from the motion (the labelling the metrics use)."""
    layout = FeatureLayout(dataset.skeleton.num_joints)
    f = canonicalize_start(features.double(), layout, angle=torch.tensor(float(heading), dtype=torch.float64))
    f = translate_features(f, torch.tensor([float(o) for o in offset], dtype=torch.float64), layout)
    m = features_to_motion(f, dataset.skeleton, dataset.fps)
    m.foot_contacts = foot_contacts(m.positions, m.fps, m.skeleton, ContactThresholds())
    return m


def case_ground_truth(case: dict, dataset=None) -> Motion:
    """The ground-truth motion of a case (its clip crop, moved as the case says).

    ``dataset``: an open `MotionDataset` holding the clip (default: opened from ``case["source"]``)."""
    src = case["source"]
    if dataset is None:
        dataset = _open_dataset(src["data"], src["split"])
    rec = next((i for i, r in enumerate(dataset.clips) if r["clip_id"] == src["clip_id"]), None)
    if rec is None:
        raise KinemaError(f"case {case['id']}: clip {src['clip_id']!r} is not in {dataset.dir} ({dataset.split})")
    feats = dataset[rec]["features"][src["start"] : src["start"] + src["frames"]]
    if feats.shape[0] != src["frames"]:
        raise KinemaError(f"case {case['id']}: clip {src['clip_id']!r} is shorter than the case's crop")
    return ground_truth_motion(feats, dataset, src["heading"], src["offset"])


# ----------------------------------------------------------------------------- constraint extraction
class _Extractor:
    """Constraint JSON objects read off a GT motion."""

    def __init__(self, motion: Motion):
        self.m = motion
        self.G, self.P = motion.global_transforms()
        feats = motion_to_features(motion.to(torch.float64))
        layout = FeatureLayout(motion.num_joints)
        self.root_xz = feats[:, layout.root_xz]
        self.heading = feats[:, layout.slices["heading"]]
        self.T = motion.num_frames

    @staticmethod
    def _list(x: torch.Tensor) -> list:
        return x.double().tolist()

    def fullbody(self, frames: list[int]) -> dict:
        return {"type": "fullbody", "frame_indices": frames,
                "local_joints_rot": self._list(quat_to_axis_angle(self.m.local_rotations[frames].double())),
                "root_positions": self._list(self.m.root_translation[frames]),
                "smooth_root_2d": self._list(self.root_xz[frames])}

    def effector(self, name: str, frames: list[int], what: str) -> dict:
        j = _joint_index(self.m, name)
        out = {"type": name, "frame_indices": frames}
        if what in ("positions", "both"):
            out["positions"] = self._list(self.P[frames, j])
        if what in ("rotations", "both"):
            out["rotations"] = self._list(quat_to_axis_angle(self.G[frames, j].double()))
        out["smooth_root_2d"] = self._list(self.root_xz[frames])
        return out

    def root2d(self, frames: list[int], heading: bool, dense: bool) -> dict:
        out = {"type": "root2d", "frame_indices": frames, "smooth_root_2d": self._list(self.root_xz[frames])}
        if heading:
            out["global_root_heading"] = self._list(self.heading[frames])
        if dense:
            out["dense"] = True
        return out


def _effector_role(name: str) -> str:
    return name.replace("-", "_")


def _joint_index(motion: Motion, type_name: str) -> int:
    role = _effector_role(type_name)
    roles = motion.skeleton.roles
    role = {"left_foot": "left_ankle", "right_foot": "right_ankle"}.get(role, role)
    return roles[role]


def _num_keyframes(rng: random.Random, limit: int) -> int:
    ks = list(range(1, max(1, min(MAX_KEYFRAMES, limit)) + 1))
    return rng.choices(ks, weights=[1.0 / k for k in ks])[0]


def _sparse_frames(rng: random.Random, T: int, lo: int = 0) -> list[int]:
    pool = range(lo, T)
    return sorted(rng.sample(pool, _num_keyframes(rng, len(pool))))


def _constraints_for(kind: str, ex: _Extractor, rng: random.Random) -> tuple[list[dict], int | None]:
    """(constraints, number of keyframes per constraint or None) of one kind on a GT motion."""
    T = ex.T
    if kind == "fullbody_sparse":
        frames = _sparse_frames(rng, T)
        return [ex.fullbody(frames)], len(frames)
    if kind == "inbetween":
        where = rng.choice(("start", "end", "both"))
        b = rng.randint(*INBETWEEN_BLOCK)
        frames = (list(range(b)) if where != "end" else []) + (list(range(T - b, T)) if where != "start" else [])
        return [ex.fullbody(frames)], len(frames)
    if kind == "end_effector":
        names = sorted(rng.sample(EFFECTORS, rng.randint(1, len(EFFECTORS))), key=EFFECTORS.index)
        k = _num_keyframes(rng, T)
        out = []
        for name in names:
            what = rng.choices(("positions", "rotations", "both"), weights=(0.4, 0.2, 0.4))[0]
            out.append(ex.effector(name, sorted(rng.sample(range(T), k)), what))
        return out, k
    if kind == "waypoints":
        frames = _sparse_frames(rng, T, lo=1)
        return [ex.root2d(frames, heading=rng.random() < 0.5, dense=False)], len(frames)
    if kind == "path":
        n = rng.randint(max(2, min(T, round(T / 3))), T)
        a = rng.randint(0, T - n)
        return [ex.root2d(list(range(a, a + n)), heading=rng.random() < 0.5, dense=True)], None
    raise KinemaError(f"unknown case kind {kind!r}")


# ----------------------------------------------------------------------------- the suite
def _case(idx: int, kind: str, rec: dict, data_dir: Path, split: str, fps: float, start: int, frames: int,
          seconds: float, with_text: bool, perturbed: bool, heading: float, offset, constraints, parts,
          num_keyframes) -> dict:
    caption = rec["captions"][0] if rec["captions"] else ""
    return {
        "id": f"{idx:04d}-{kind}", "kind": kind, "parts": parts, "clip_id": rec["clip_id"],
        "caption": caption, "prompt": caption if with_text else "", "with_text": with_text,
        "seconds": seconds, "num_frames": round(seconds * fps), "fps": fps, "heading": heading,
        "perturbed": perturbed, "num_keyframes": num_keyframes,
        "source": {"data": str(data_dir), "split": split, "clip_id": rec["clip_id"], "start": start,
                   "frames": frames, "heading": heading, "offset": list(offset)},
        "constraints": constraints,
    }


def build_suite(data_dir, split: str = "test", num_cases: int = 100, seed: int = 0,
                text_fraction: float = 0.3, perturb_fraction: float = PERTURB_FRACTION) -> list[dict]:
    """``num_cases`` cases drawn deterministically (for ``seed``) from the clips of ``split``.

    About ``text_fraction`` of them are ``text`` cases (distinct clips; at least one); the rest cycle
    through the constrained kinds in :data:`CONSTRAINED_KINDS`, alternating with/without text within
    each kind. Constrained cases need clips of at least 3 s."""
    if num_cases < 1:
        raise KinemaError(f"the suite needs at least one case, got {num_cases}")
    data_dir = Path(data_dir).resolve()
    ds = _open_dataset(data_dir, split)
    if len(ds) == 0:
        raise KinemaError(f"{data_dir}: split {split!r} has no clips")
    fps = ds.fps
    lo, hi = round(MIN_SECONDS * fps), round(MAX_SECONDS * fps)
    rng = random.Random(f"kinema-suite:{seed}")
    order = list(range(len(ds)))
    rng.shuffle(order)
    long_enough = [i for i in order if ds.clips[i]["length"] >= lo]
    n_text = max(1, min(len(ds), round(num_cases * text_fraction))) if long_enough else num_cases
    n_text = min(n_text, num_cases)
    if num_cases > n_text and not long_enough:
        raise KinemaError(f"{data_dir}: no clip of split {split!r} lasts {MIN_SECONDS:g} s "
                          "(needed for constrained cases)")
    cases: list[dict] = []
    for k in range(n_text):
        i = order[k % len(order)]
        rec = ds.clips[i]
        n = min(rec["length"], hi)
        start = rng.randint(0, rec["length"] - n)
        seconds = min(max(n, lo), hi) / fps
        cases.append(_case(len(cases), "text", rec, data_dir, split, fps, start, n, seconds, True, False,
                           0.0, (0.0, 0.0), [], [], None))
    counts = dict.fromkeys(CONSTRAINED_KINDS, 0)
    for k in range(num_cases - n_text):
        kind = CONSTRAINED_KINDS[k % len(CONSTRAINED_KINDS)]
        with_text = counts[kind] % 2 == 0
        counts[kind] += 1
        ci = long_enough[k % len(long_enough)]
        rec = ds.clips[ci]
        n = rng.randint(lo, min(hi, rec["length"]))
        start = rng.randint(0, rec["length"] - n)
        perturbed = rng.random() < perturb_fraction
        heading = rng.uniform(-math.pi, math.pi) if perturbed else 0.0
        offset = (rng.uniform(-PERTURB_METRES, PERTURB_METRES), rng.uniform(-PERTURB_METRES, PERTURB_METRES)) \
            if perturbed else (0.0, 0.0)
        feats = ds[ci]["features"][start : start + n]
        ex = _Extractor(ground_truth_motion(feats, ds, heading, offset))
        parts = sorted(rng.sample(_MIXABLE, 2), key=_MIXABLE.index) if kind == "mixed" else [kind]
        constraints, nk = [], None
        for part in parts:
            cs, kk = _constraints_for(part, ex, rng)
            constraints += cs
            nk = kk if kind != "mixed" else None
        cases.append(_case(len(cases), kind, rec, data_dir, split, fps, start, n, n / fps, with_text, perturbed,
                           heading, offset, constraints, parts, nk))
    return cases


def save_suite(cases: list[dict], path) -> Path:
    """Write the suite as JSON (atomically); :func:`load_suite` reads it back unchanged."""
    from kinema.atomic_files import atomic_write_bytes

    doc = {"format": SUITE_FORMAT, "version": SUITE_VERSION, "cases": cases}
    path = Path(path)
    atomic_write_bytes(path, (json.dumps(doc, indent=1, allow_nan=False) + "\n").encode("utf-8"))
    return path


def load_suite(path) -> list[dict]:
    """The cases of a suite file written by :func:`save_suite` (``KinemaError`` when unreadable)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise KinemaError(f"{path}: no such suite file") from None
    except (OSError, ValueError) as exc:
        raise KinemaError(f"{path}: cannot read suite: {exc}") from None
    except RecursionError:
        raise KinemaError(f"{path}: cannot read suite: JSON nested too deeply") from None
    if not isinstance(doc, dict) or doc.get("format") != SUITE_FORMAT or not isinstance(doc.get("cases"), list):
        raise KinemaError(f"{path}: not a kinema evaluation suite (expected format {SUITE_FORMAT!r})")
    if doc.get("version") != SUITE_VERSION:
        raise KinemaError(f"{path}: suite version {doc.get('version')!r}, this kinema reads {SUITE_VERSION}")
    for c in doc["cases"]:
        if not isinstance(c, dict) or c.get("kind") not in CASE_KINDS or "source" not in c:
            raise KinemaError(f"{path}: malformed case {str(c)[:120]}")
    return doc["cases"]


# ----------------------------------------------------------------------------- scoring targets
def case_targets(case: dict, skeleton) -> dict:
    """World-space scoring targets recomputed from a case's constraints.

    Returns ``{"fullbody": [(frames, positions (K, J, 3))], "end_effector": [(joint index, frames,
    positions (K, 3) | None, quats (K, 4) | None)], "root2d": [(frames, xz (K, 2))]}`` (float64, metres);
    dense paths are expanded to every frame of their interval (linear interpolation)."""
    out: dict = {"fullbody": [], "end_effector": [], "root2d": []}
    for c in case["constraints"]:
        frames = list(c["frame_indices"])
        t = c["type"]
        if t == "fullbody":
            q = axis_angle_to_quat(torch.tensor(c["local_joints_rot"], dtype=torch.float64))
            _, P = forward_kinematics(q, torch.tensor(c["root_positions"], dtype=torch.float64),
                                      skeleton.offsets.double(), skeleton.parents)
            out["fullbody"].append((frames, P))
        elif t in EFFECTORS or t == "end-effector":
            name = c.get("joint", t)
            role = {"left-foot": "left_ankle", "right-foot": "right_ankle", "left_foot": "left_ankle",
                    "right_foot": "right_ankle"}.get(name, _effector_role(name))
            j = skeleton.roles[role] if role in skeleton.roles else skeleton.index(name)
            pos = torch.tensor(c["positions"], dtype=torch.float64) if "positions" in c else None
            rot = axis_angle_to_quat(torch.tensor(c["rotations"], dtype=torch.float64)) if "rotations" in c else None
            out["end_effector"].append((j, frames, pos, rot))
        elif t == "root2d":
            xz = torch.tensor(c["smooth_root_2d"], dtype=torch.float64)
            if c.get("dense") and len(frames) > 1:
                full = torch.arange(frames[0], frames[-1] + 1, dtype=torch.float64)
                f = torch.tensor(frames, dtype=torch.float64)
                xz = torch.stack([_interp(full, f, xz[:, i]) for i in range(2)], dim=-1)
                frames = [int(x) for x in full.tolist()]
            out["root2d"].append((frames, xz))
    return out


def _interp(x: torch.Tensor, xp: torch.Tensor, fp: torch.Tensor) -> torch.Tensor:
    idx = torch.searchsorted(xp, x).clamp(1, len(xp) - 1)
    x0, x1 = xp[idx - 1], xp[idx]
    w = ((x - x0) / (x1 - x0)).clamp(0, 1)
    return fp[idx - 1] * (1 - w) + fp[idx] * w
