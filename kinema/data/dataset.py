"""`MotionDataset`: read a cache written by kinema.data.build (one split of it) for training.

The whole ``features.safetensors`` tensor is loaded once (about 0.5 GB for the full Bandai Namco
build with mirroring at 20 fps) and items are views into it, so ``__getitem__`` costs nothing and
DataLoader workers forked from the parent share the memory. Every file is checked when the dataset
is opened, so a stale or truncated cache fails here with the path in the message, not deep inside
a training step.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import torch

from kinema.data.build import FILES, FORMAT_VERSION
from kinema.errors import DataError, KinemaError
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.skeleton import Skeleton

SPLIT_CHOICES = ("train", "val", "test", "all")


def _read_json(path: Path):
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{path}: missing (is this a `kinema data build` output folder?)") from None
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read: {exc}") from None


def load_clip_table(dir: str | Path) -> tuple[dict, list[dict]]:
    """(meta.json, clips.json) of a build, without loading features (for summaries such as
    `kinema data stats`). Raises `DataError` naming the path when either is missing or malformed."""
    d = Path(dir)
    if not d.is_dir():
        raise DataError(f"{d}: dataset folder does not exist (run `kinema data build` first)")
    meta, clips = _read_json(d / "meta.json"), _read_json(d / "clips.json")
    keys = ("clip_id", "content", "style", "split", "mirrored", "duration_s", "length")
    if not isinstance(meta, dict) or not isinstance(clips, list):
        raise DataError(f"{d}: meta.json must hold an object and clips.json a list")
    for r in clips:
        if not isinstance(r, dict) or any(k not in r for k in keys):
            raise DataError(f"{d / 'clips.json'}: record lacks one of {keys}: {str(r)[:200]}")
    return meta, clips


def _refuse_multirig(d: Path) -> None:
    """A multi-rig motion cache without flat features cannot train today's flat human model: say why."""
    meta_path = d / "meta.json"
    if (d / "features.safetensors").is_file() or not meta_path.is_file():
        return
    meta = _read_json(meta_path)
    if isinstance(meta, dict) and meta.get("format") == "kinema-motions":
        why = meta.get("not_trainable_because") or "it holds motions on several skeletons"
        raise DataError(
            f"{d}: a multi-rig motion cache ({meta.get('dataset', '?')}) that the current flat human trainer "
            f"cannot use: {why}; it needs one skeleton with pelvis, hips, ankles and toes "
            "(train an any-rig model on it instead: kinema train-anyrig --data DIR --out RUN, docs/anyrig.md)"
        )


class MotionDataset(torch.utils.data.Dataset):
    """Clips of one split (``"train"``, ``"val"``, ``"test"`` or ``"all"``) of a dataset build.

    ``ds[i]`` is ``{"features": (T, D) float32 tensor, "captions": [str, ...], "clip": {...}}`` where
    ``clip`` is the clip's record from clips.json (labels, split, mirrored, fps, path, ...).
    Attributes: ``stats`` (train-split NormStats), ``skeleton``, ``fps``, ``layout``, ``meta``,
    ``clips`` (the records of this split).
    """

    def __init__(self, dir: str | Path, split: str = "train"):
        self.dir = Path(dir)
        if split not in SPLIT_CHOICES:
            raise DataError(f"unknown split {split!r}; choose one of {', '.join(SPLIT_CHOICES)}")
        if not self.dir.is_dir():
            raise DataError(f"{self.dir}: dataset folder does not exist (run `kinema data build` first)")
        _refuse_multirig(self.dir)
        for name in FILES:
            if not (self.dir / name).is_file():
                raise DataError(f"{self.dir / name}: missing (is this a `kinema data build` output folder?)")
        self.split = split
        self.meta, records = load_clip_table(self.dir)
        if self.meta.get("format_version") != FORMAT_VERSION:
            raise DataError(
                f"{self.dir / 'meta.json'}: format version {self.meta.get('format_version')!r}, "
                f"this kinema reads {FORMAT_VERSION}; rebuild the dataset"
            )
        try:
            self.skeleton = Skeleton.from_dict(_read_json(self.dir / "skeleton.json"))
            self.stats = NormStats.from_dict(_read_json(self.dir / "stats.json"))
            self.fps = float(self.meta["fps"])
        except DataError:
            raise
        except (KeyError, TypeError, ValueError, RuntimeError, KinemaError) as exc:
            raise DataError(f"{self.dir}: malformed skeleton.json, stats.json or meta.json ({exc})") from None
        self.layout = FeatureLayout(self.skeleton.num_joints)
        if self.meta.get("layout") != self.layout.to_dict():
            raise DataError(
                f"{self.dir / 'meta.json'}: feature layout {self.meta.get('layout')} does not match the "
                f"{self.skeleton.num_joints}-joint layout of this kinema version; rebuild the dataset"
            )
        D = self.layout.dim
        if self.stats.mean.shape != (D,) or self.stats.std.shape != (D,):
            raise DataError(
                f"{self.dir / 'stats.json'}: statistics have {self.stats.mean.numel()} channels, expected {D}"
            )
        self.features = self._load_features(D)
        total = self.features.shape[0]
        for r in records:
            try:
                ok = 0 <= r["start"] and r["length"] > 0 and r["start"] + r["length"] <= total
            except (KeyError, TypeError):
                ok = False
            if not ok:
                raise DataError(f"{self.dir / 'clips.json'}: bad record {str(r)[:200]} for {total} feature rows")
        self.clips = records if split == "all" else [r for r in records if r["split"] == split]

    def _load_features(self, D: int) -> torch.Tensor:
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        path = self.dir / "features.safetensors"
        try:
            tensors = load_file(str(path))
        except (SafetensorError, OSError, ValueError) as exc:
            raise DataError(f"{path}: cannot read: {exc}") from None
        x = tensors.get("features")
        if x is None or x.ndim != 2 or x.shape[1] != D or x.dtype != torch.float32:
            shape = None if x is None else (tuple(x.shape), str(x.dtype))
            raise DataError(f"{path}: expected a float32 tensor 'features' of shape (N, {D}), got {shape}")
        return x

    def keep_datasets(self, names: Sequence[str]) -> None:
        """Keep only the clips whose ``dataset`` (clips.json) is one of ``names``; a name no clip of this
        split has is a one-line error (a typo would otherwise train or evaluate on nothing)."""
        have = {rec.get("dataset", "") for rec in self.clips}
        unknown = sorted(set(names) - have)
        if unknown:
            raise DataError(f"{self.dir / 'clips.json'}: no {self.split} clip comes from dataset "
                            f"{', '.join(map(repr, unknown))} (it has {', '.join(sorted(have))})")
        self.clips = [rec for rec in self.clips if rec.get("dataset", "") in names]

    def __len__(self) -> int:
        return len(self.clips)

    def __getitem__(self, i: int) -> dict:
        if not -len(self) <= i < len(self):
            raise IndexError(f"index {i} out of range for {len(self)} clips")
        rec = self.clips[i]
        feats = self.features[rec["start"] : rec["start"] + rec["length"]]
        return {"features": feats, "captions": list(rec["captions"]), "clip": rec}

    @property
    def num_frames(self) -> int:
        """Frames in this split."""
        return sum(r["length"] for r in self.clips)

    def __repr__(self) -> str:
        return f"MotionDataset({str(self.dir)!r}, split={self.split!r}, {len(self)} clips @ {self.fps:g} fps)"
