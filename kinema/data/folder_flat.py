"""Flat human features for a folder build whose clips all share one human skeleton.

Today's trainer (`kinema train`) reads the flat Kimodo feature cache of kinema.data.build
(``features.safetensors``, ``skeleton.json``, ``stats.json`` and a ``layout`` in meta.json). When
every clip of ``kinema data build folder`` is on one skeleton with the locomotion roles (pelvis,
hips, ankles, toes, found by name as in kinema.skeleton), those files are written next to the
motion cache, so the same folder trains like a Bandai Namco build. Joints above the pelvis (a
static ``joint_Root``, a ``Reference`` bone) are pruned so the pelvis is the root, as for Bandai.
`flat_blocker` says in words why a build cannot be trained yet otherwise.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from kinema.data.build import FORMAT_VERSION, with_clean_rest_pose
from kinema.data.build_folder import write_json
from kinema.data.sources import SourceFile
from kinema.errors import DataError, KinemaError
from kinema.motion.contacts import ContactThresholds
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS
from kinema.representation.kimodo_features import motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.representation.transform import canonicalize_start
from kinema.skeleton import LOCOMOTION_ROLES, Skeleton


def flat_blocker(files: list[SourceFile], rigs: int) -> str | None:
    """Why the flat trainer cannot use this build (None when it can)."""
    if rigs != 1:
        return f"{rigs} different skeletons; the current trainer needs every clip on one skeleton"
    skel = files[0].skeleton
    missing = [r for r in LOCOMOTION_ROLES if r not in skel.roles]
    if missing:
        return f"skeleton of {files[0].rel} has no joint for {', '.join(missing)} (needs a human rig)"
    return None


def _pelvis_rooted(motion: Motion) -> Motion:
    """``motion`` with every ancestor of the pelvis pruned, so the pelvis is joint 0."""
    skel = motion.skeleton
    pelvis = skel.roles["pelvis"]
    above = [skel.names[j] for j in skel.path_from_root(pelvis) if j != pelvis]
    return motion.prune(above) if above else motion


def write_flat(tmp: Path, files: dict[str, SourceFile], records: list[dict], fps: float) -> dict:
    """Write features.safetensors, skeleton.json and stats.json for ``records`` (in cache order)
    into ``tmp``; returns the meta.json keys MotionDataset needs (layout, ...)."""
    from safetensors.torch import save_file

    feats, skeleton = [], None
    for rec in records:
        motion = _pelvis_rooted(files[rec["path"]].clips[rec["clip_name"]])
        try:
            f = motion_to_features(motion).to(torch.float32)
        except (KinemaError, ValueError) as exc:
            raise DataError(f"{rec['path']}: cannot compute features: {exc}") from None
        if f.shape[0] != rec["length"]:
            raise DataError(f"{rec['path']}: {f.shape[0]} feature frames, expected {rec['length']}")
        feats.append(f.numpy())
        skeleton = skeleton or motion.skeleton
    offsets = skeleton.offsets.clone()
    offsets[0] = torch.tensor([0.0, float(offsets[0, 1]), 0.0], dtype=offsets.dtype)
    skeleton = Skeleton(skeleton.names, skeleton.parents, offsets, end_sites=skeleton.end_sites, name=skeleton.name)
    skeleton = with_clean_rest_pose(skeleton, feats, records, fps)
    layout = FeatureLayout(skeleton.num_joints)
    train = [torch.from_numpy(f) for f, r in zip(feats, records, strict=True) if r["split"] == "train"]
    if not train:
        raise DataError("no clip is in the train split; add more clips")
    stats = NormStats.compute((canonicalize_start(f, layout) for f in train), xz_pairs=layout.xz_pairs())
    features = torch.from_numpy(np.concatenate(feats, axis=0)).contiguous()
    save_file(
        {"features": features},
        str(tmp / "features.safetensors"),
        metadata={"format": "kinema-features", "fps": str(float(fps)), "dim": str(layout.dim)},
    )
    write_json(tmp / "skeleton.json", skeleton.to_dict())
    write_json(tmp / "stats.json", stats.to_dict(), indent=None)
    return {
        "flat_format_version": FORMAT_VERSION,
        "layout": layout.to_dict(),
        "root_sigma_s": DEFAULT_ROOT_SIGMA_SECONDS,
        "contact_thresholds": asdict(ContactThresholds()),
        "mirror": False,
    }
