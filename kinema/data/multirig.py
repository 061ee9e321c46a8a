"""One multi-rig training set from several builds: motion caches, flat human builds, manifests.

A *manifest* is a small JSON file that lists built datasets to train on together::

    {"format": "kinema-manifest", "version": 1,
     "datasets": [{"path": "quat20"}, {"path": "bandai20", "exclude_flags": []}]}

Paths are relative to the manifest's folder. Each entry is either a multi-rig motion cache
(``kinema data build quaternius`` / ``folder``) or a flat human build (``kinema data build
bandai-namco``), whose motions are recovered exactly (up to float32) from its features: pelvis
position and every joint's rotation are stored there. ``exclude_flags`` (default ``["prop"]``)
drops clips carrying any of those flags. Write one with ``kinema data manifest``.

`MultiRigData` reads a manifest, or one build directly, and offers every clip as a `Motion` in
normalised units (rest pose 1 unit across, as in the motion caches) with its rig id, captions,
flags and split: the per-rig input of the any-rig trainer, which computes its own features.
"""

from __future__ import annotations

import json
from pathlib import Path

from kinema.data.motion_cache import MotionCache, is_motion_cache, rest_extent, topology_key
from kinema.errors import DataError
from kinema.motion.core import Motion
from kinema.representation.kimodo_features import features_to_motion

MANIFEST_FORMAT = "kinema-manifest"
DEFAULT_EXCLUDE = ("prop",)


def write_manifest(path: str | Path, dirs: list[str | Path], exclude_flags=DEFAULT_EXCLUDE) -> dict:
    """Write a manifest at ``path`` listing ``dirs`` (checked to be builds); returns its contents."""
    from kinema.atomic_files import atomic_write_text, check_output_path

    path = check_output_path(path).absolute()
    entries = []
    for d in dirs:
        d = Path(d).absolute()
        _open(d)  # fail now, naming the folder, rather than at training time
        try:
            rel = d.relative_to(path.parent).as_posix()
        except ValueError:
            rel = str(d)
        entries.append({"path": rel, "exclude_flags": list(exclude_flags)})
    obj = {"format": MANIFEST_FORMAT, "version": 1, "datasets": entries}
    atomic_write_text(path, json.dumps(obj, indent=1) + "\n")
    return obj


def read_manifest(path: Path) -> list[tuple[Path, tuple[str, ...]]]:
    """(build folder, excluded flags) for each entry of a manifest file."""
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read manifest: {exc}") from None
    if not isinstance(obj, dict) or obj.get("format") != MANIFEST_FORMAT or obj.get("version") != 1:
        raise DataError(f"{path}: not a {MANIFEST_FORMAT} version 1 file")
    out = []
    for i, e in enumerate(obj.get("datasets") or []):
        if not isinstance(e, dict) or not isinstance(e.get("path"), str):
            raise DataError(f"{path}: datasets[{i}] needs a 'path' string")
        unknown = set(e) - {"path", "exclude_flags"}
        if unknown:
            raise DataError(f"{path}: datasets[{i}] has unknown keys {sorted(unknown)}")
        out.append((path.parent / e["path"], tuple(e.get("exclude_flags", DEFAULT_EXCLUDE))))
    if not out:
        raise DataError(f"{path}: lists no datasets")
    return out


class _FlatSource:
    """A flat human build seen as one rig: motions recovered from its features."""

    def __init__(self, dir: Path):
        from kinema.data.dataset import MotionDataset

        self.ds = MotionDataset(dir, "all")
        self.dataset = self.ds.meta.get("dataset", "flat")
        skel = self.ds.skeleton
        self.scale = 1.0 / rest_extent(skel)
        self.skeleton = skel.scaled(self.scale)
        self.rig = {
            "rig": self.dataset,
            "topology": topology_key(skel),
            "joints": skel.num_joints,
            "scale": self.scale,
            "files": [],
            "split": "mixed",
        }
        self.clips = [dict(r, rig=self.dataset, flags=r.get("flags", [])) for r in self.ds.clips]

    def motion(self, i: int) -> Motion:
        m = features_to_motion(self.ds[i]["features"].double(), self.ds.skeleton, self.ds.fps)
        return Motion(self.skeleton, m.fps, m.root_translation * self.scale, m.local_rotations)


def _open(d: Path):
    if is_motion_cache(d):
        return MotionCache(d)
    if (d / "features.safetensors").is_file():
        return _FlatSource(d)
    raise DataError(f"{d}: neither a motion cache nor a flat build (run `kinema data build` first)")


class MultiRigData:
    """Clips of several builds (a manifest, or one build folder) as normalised motions.

    ``data.clips[i]`` is the clip's record plus ``"dataset"``; ``data.motion(i)`` its `Motion`;
    ``data.rigs`` maps rig id -> rig record; ``split`` keeps one split ("all" keeps every clip);
    ``exclude_flags`` applies to a build folder given directly (a manifest names its own).
    """

    def __init__(self, path: str | Path, split: str = "all", exclude_flags: tuple[str, ...] | None = None):
        path = Path(path)
        direct = DEFAULT_EXCLUDE if exclude_flags is None else tuple(exclude_flags)
        entries = read_manifest(path) if path.is_file() else [(path, direct)]
        self.sources, self.clips, self.rigs, self._index = [], [], {}, []
        for d, exclude in entries:
            src = _open(d)
            name = src.meta.get("dataset", d.name) if isinstance(src, MotionCache) else src.dataset
            rigs = src.rigs if isinstance(src, MotionCache) else {src.rig["rig"]: src.rig}
            for rid, rig in rigs.items():
                if rid in self.rigs and self.rigs[rid]["topology"] != rig["topology"]:
                    raise DataError(f"{d}: rig id {rid!r} is already used by another skeleton")
                self.rigs[rid] = rig
            k = len(self.sources)
            self.sources.append(src)
            for i, rec in enumerate(src.clips):
                if (split != "all" and rec["split"] != split) or set(rec.get("flags", ())) & set(exclude):
                    continue
                self.clips.append(dict(rec, dataset=name))
                self._index.append((k, i))

    def motion(self, i: int) -> Motion:
        k, j = self._index[i]
        return self.sources[k].motion(j)

    def __len__(self) -> int:
        return len(self.clips)

    def frames(self) -> int:
        return sum(r["length"] for r in self.clips)
