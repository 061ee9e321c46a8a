"""The multi-rig motion cache: motions on many skeletons, stored as rotations, not model features.

A cache written by ``kinema data build quaternius`` or ``kinema data build folder`` is a folder::

    DIR/motions.safetensors  per rig R: "R/root_translation" (N_R, 3) and "R/local_rotations"
                             (N_R, J_R, 4) float32, the rig's clips end to end at the cache's fps;
                             "R/local_translations" (N_R, J_R, 3) too when some clip of the rig
                             animates bone translations (Motion.local_translations; other clips
                             of that rig store their rest offsets there)
    DIR/clips.json           one record per kept clip: rig, skeleton (a key of skeletons.json),
                             start/length (rows of its rig's tensors), fps, duration_s, captions,
                             flags, path (source file), clip_name, action, hash, duplicates, split
    DIR/rigs.json            one record per rig (skeleton topology): joints, names, parents, scale,
                             files using it, clips, seconds, split
    DIR/skeletons.json       {skeleton key: Skeleton.to_dict() + "scale"}: one per source file
                             (files on one rig share names and parents but not proportions)
    DIR/meta.json            "format": "kinema-motions", version, dataset, fps, units, counts, ...

Units: lengths are *normalised* per source file: a file's rest pose is scaled so its largest
extent is 1 (``scale`` = normalised / metres, stored per file and per rig). Y up; quaternions
``(w, x, y, z)`` local to the parent; all-identity is the skeleton's rest pose (rest_rotations
hold the bind pose). Per-joint model features are *not* stored: the trainer computes them from
these motions with the representation of its choice.

Why this shape: rigs differ in joint count, so each rig gets its own two tensors and a clip is a
row range in them; a single safetensors file loads without pickle; every choice (dedup, split,
captions, flags) stays inspectable as JSON.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from kinema.errors import DataError
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

FORMAT = "kinema-motions"
FORMAT_VERSION = 1
FILES = ("motions.safetensors", "clips.json", "rigs.json", "skeletons.json", "meta.json")
#: Decimals kept when hashing animation data (1e-5 rad / body sizes: far below what the eye sees).
HASH_DECIMALS = 5


def topology_key(skeleton: Skeleton) -> str:
    """A short id of a skeleton's topology (joint names and parents), equal for files sharing a rig."""
    text = json.dumps([list(skeleton.names), list(skeleton.parents)])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def rest_extent(skeleton: Skeleton, ignore: Iterable[str] = ()) -> float:
    """Largest side of the bounding box of the rest-pose joint positions (in the skeleton's units).

    The rest pose is the bind pose (``rest_rotations``, identity when absent). ``ignore`` names
    joints left out, e.g. helper bones (IK targets) that sit away from the body.
    """
    J = skeleton.num_joints
    rot = skeleton.rest_rotations
    if rot is None:
        rot = torch.zeros(J, 4, dtype=torch.float64)
        rot[:, 0] = 1.0
    m = Motion(skeleton, 1.0, torch.zeros(1, 3, dtype=torch.float64), rot[None].double())
    P = m.positions[0]
    skip = set(ignore)
    keep = [j for j, n in enumerate(skeleton.names) if n not in skip] or list(range(J))
    P = P[keep]
    return float((P.max(0).values - P.min(0).values).max())


def motion_hash(motion: Motion) -> str:
    """SHA-256 (16 hex digits) of a clip's animation data: topology, local rotations and root path in
    source units (hash before per-file normalisation), rounded to `HASH_DECIMALS`; rotations are
    sign-canonicalised (w >= 0) so q and -q agree.

    Bone lengths and bone translations are left out: files of one rig with other proportions
    carry the same animation with translation channels that differ only by their rest offsets
    (Bull and Cow's Attack_Kick, 20 cute fish's Attack: measured on the shared files), and those
    count as one clip."""
    q = motion.local_rotations.double()
    q = torch.where(q[..., :1] < 0, -q, q)
    parts = (
        topology_key(motion.skeleton).encode(),
        np.round(q.numpy(), HASH_DECIMALS).tobytes(),
        np.round(motion.root_translation.double().numpy(), HASH_DECIMALS).tobytes(),
    )
    h = hashlib.sha256()
    for p in parts:
        h.update(p)
    return h.hexdigest()[:16]


def travel(motion: Motion) -> float:
    """Net horizontal (x, z) distance the joints' centroid moves from the first to the last frame.

    Net rather than largest distance, so a run animated on the spot (whose centroid sways by up
    to 0.2 body sizes within a stride, measured on the Quaternius runs) reads as ~0."""
    c = motion.positions.mean(dim=1)[:, [0, 2]]
    return float((c[-1] - c[0]).norm())


@dataclass
class CacheWriter:
    """Collects rigs, skeletons and clips, then writes the cache files into a folder.

    ``add_clip`` appends a motion (already normalised, at the cache fps) to its rig's tensors and
    records it; ``write(folder, meta)`` writes every file. Rigs are keyed by `topology_key`.
    """

    fps: float
    rigs: dict[str, dict] = field(default_factory=dict)
    skeletons: dict[str, dict] = field(default_factory=dict)
    clips: list[dict] = field(default_factory=list)
    _roots: dict[str, list] = field(default_factory=dict)
    _rots: dict[str, list] = field(default_factory=dict)
    _trans: dict[str, list] = field(default_factory=dict)

    def add_skeleton(self, key: str, skeleton: Skeleton, scale: float, rig_id: str) -> None:
        """Register one source file's skeleton (normalised) under ``key`` on rig ``rig_id``."""
        d = skeleton.to_dict()
        d["scale"] = scale
        d["rig"] = rig_id
        self.skeletons[key] = d
        rig = self.rigs.setdefault(
            rig_id,
            {
                "rig": rig_id,
                "topology": topology_key(skeleton),
                "joints": skeleton.num_joints,
                "names": list(skeleton.names),
                "parents": list(skeleton.parents),
                "scale": scale,
                "file_scales": {},
                "files": [],
                "clips": 0,
                "frames": 0,
                "seconds": 0.0,
                "split": None,
                "animated_translations": False,
            },
        )
        if list(skeleton.names) != rig["names"] or list(skeleton.parents) != rig["parents"]:
            raise DataError(f"{key}: skeleton topology differs from rig {rig_id}")
        rig["files"].append(key)
        rig["file_scales"][key] = scale

    def add_clip(self, motion: Motion, record: dict) -> None:
        """Append ``motion`` to the tensors of ``record["rig"]`` and keep ``record`` (start/length set)."""
        rig_id = record["rig"]
        if rig_id not in self.rigs:
            raise DataError(f"clip {record.get('clip_id')}: unknown rig {rig_id}")
        rig = self.rigs[rig_id]
        roots, rots = self._roots.setdefault(rig_id, []), self._rots.setdefault(rig_id, [])
        record["start"] = rig["frames"]
        record["length"] = motion.num_frames
        record["fps"] = self.fps
        record["duration_s"] = motion.num_frames / self.fps
        roots.append(motion.root_translation.to(torch.float32))
        rots.append(motion.local_rotations.to(torch.float32))
        self._trans.setdefault(rig_id, []).append(motion.translations_or_offsets().to(torch.float32))
        if motion.local_translations is not None:
            rig["animated_translations"] = True
        rig["frames"] += motion.num_frames
        rig["clips"] += 1
        rig["seconds"] += record["duration_s"]
        self.clips.append(record)

    def tensors(self) -> dict[str, torch.Tensor]:
        """The safetensors payload: two contiguous tensors per rig."""
        out = {}
        for rig_id in self.rigs:
            if rig_id in self._roots:
                out[f"{rig_id}/root_translation"] = torch.cat(self._roots[rig_id]).contiguous()
                out[f"{rig_id}/local_rotations"] = torch.cat(self._rots[rig_id]).contiguous()
                if self.rigs[rig_id]["animated_translations"]:
                    out[f"{rig_id}/local_translations"] = torch.cat(self._trans[rig_id]).contiguous()
        return out

    def write(self, folder: Path, meta: dict) -> dict:
        """Write all cache files into ``folder`` (an `atomic_folder` temporary); returns meta.json."""
        from safetensors.torch import save_file

        tensors = self.tensors()
        for t in tensors.values():
            if not torch.isfinite(t).all():
                raise DataError("motions contain NaN or inf")
        save_file(tensors, str(folder / "motions.safetensors"), metadata={"format": FORMAT})
        for rig in self.rigs.values():
            rig["seconds"] = round(rig["seconds"], 4)
        meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "fps": self.fps, **meta}
        for name, obj in (
            ("clips", self.clips),
            ("rigs", list(self.rigs.values())),
            ("skeletons", self.skeletons),
            ("meta", meta),
        ):
            text = json.dumps(obj, indent=1, ensure_ascii=False) + "\n"
            (folder / f"{name}.json").write_text(text, encoding="utf-8")
        return meta


def is_motion_cache(dir: str | Path) -> bool:
    """Whether ``dir`` holds a multi-rig motion cache (its meta.json says ``kinema-motions``)."""
    try:
        meta = json.loads((Path(dir) / "meta.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and meta.get("format") == FORMAT


class MotionCache:
    """A motion cache opened for reading: ``cache.motion(i)`` is clip i as a `Motion` on its own
    file's skeleton (normalised units), ``cache.clips`` the records, ``cache.rigs`` by rig id."""

    def __init__(self, dir: str | Path):
        self.dir = Path(dir)
        if not self.dir.is_dir():
            raise DataError(f"{self.dir}: dataset folder does not exist (run `kinema data build` first)")
        for name in FILES:
            if not (self.dir / name).is_file():
                raise DataError(f"{self.dir / name}: missing (is this a `kinema data build` motion cache?)")
        self.meta = _read(self.dir / "meta.json")
        if self.meta.get("format") != FORMAT or self.meta.get("format_version") != FORMAT_VERSION:
            raise DataError(
                f"{self.dir / 'meta.json'}: format {self.meta.get('format')!r} version "
                f"{self.meta.get('format_version')!r}; this kinema reads {FORMAT} {FORMAT_VERSION}"
            )
        self.fps = float(self.meta["fps"])
        self.clips: list[dict] = _read(self.dir / "clips.json")
        self.rigs: dict[str, dict] = {r["rig"]: r for r in _read(self.dir / "rigs.json")}
        self._skeleton_dicts: dict[str, dict] = _read(self.dir / "skeletons.json")
        self._skeletons: dict[str, Skeleton] = {}
        self._tensors = _load_tensors(self.dir / "motions.safetensors")
        self._check()

    def _check(self) -> None:
        """Every clip names a known rig and skeleton and lies inside its rig's tensors."""
        for rec in self.clips:
            try:
                rows = self._tensors[f"{rec['rig']}/root_translation"].shape[0]
                ok = rec["skeleton"] in self._skeleton_dicts and 0 <= rec["start"] and rec["length"] > 0
                ok = ok and rec["start"] + rec["length"] <= rows
            except (KeyError, TypeError):
                ok = False
            if not ok:
                raise DataError(f"{self.dir / 'clips.json'}: bad record {str(rec)[:200]}; rebuild the cache")

    def skeleton(self, key: str) -> Skeleton:
        """The (normalised) skeleton stored under ``key`` (a source file)."""
        if key not in self._skeletons:
            try:
                self._skeletons[key] = Skeleton.from_dict(self._skeleton_dicts[key])
            except KeyError:
                raise DataError(f"{self.dir / 'skeletons.json'}: no skeleton {key!r}") from None
        return self._skeletons[key]

    def motion(self, i: int) -> Motion:
        """Clip ``i`` as a float32 `Motion` (normalised lengths, the cache's fps)."""
        rec = self.clips[i]
        sl = slice(rec["start"], rec["start"] + rec["length"])
        root = self._tensors[f"{rec['rig']}/root_translation"][sl]
        rot = self._tensors[f"{rec['rig']}/local_rotations"][sl]
        trans = self._tensors.get(f"{rec['rig']}/local_translations")
        trans = None if trans is None else trans[sl]
        return Motion(self.skeleton(rec["skeleton"]), self.fps, root, rot, local_translations=trans)

    def __len__(self) -> int:
        return len(self.clips)


def _read(path: Path):
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read: {exc}") from None


def _load_tensors(path: Path) -> dict[str, torch.Tensor]:
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    try:
        return load_file(str(path))
    except (SafetensorError, OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read: {exc}") from None
