"""Multi-rig training sets: motion hashes, a Bandai Namco build joined through a manifest, stats."""

from __future__ import annotations

import torch

from kinema.cli import main
from kinema.data.dataset import MotionDataset
from kinema.data.motion_cache import motion_hash, rest_extent
from kinema.data.multirig import MultiRigData, write_manifest
from kinema.motion.core import Motion
from kinema.motion.features import FeatureLayout


def test_motion_hash_finds_exact_duplicates(tiny_data) -> None:
    ds = MotionDataset(tiny_data, "all")
    m = MultiRigData(tiny_data).motion(0).to(torch.float64)
    same = Motion(m.skeleton, m.fps, m.root_translation.clone(), -m.local_rotations)  # q and -q: one rotation
    assert motion_hash(m) == motion_hash(same)
    moved = Motion(m.skeleton, m.fps, m.root_translation + 1e-3, m.local_rotations)
    assert motion_hash(m) != motion_hash(moved)
    assert motion_hash(m) != motion_hash(m.crop(1))
    assert len({motion_hash(MultiRigData(tiny_data).motion(i)) for i in range(len(ds))}) == len(ds)


def test_bandai_build_joins_through_a_manifest(tiny_data, tmp_path, capsys) -> None:
    manifest = tmp_path / "multi.json"
    write_manifest(manifest, [tiny_data])
    data = MultiRigData(manifest)
    ds = MotionDataset(tiny_data, "all")
    assert len(data) == len(ds) and set(data.rigs) == {"bandai-namco"}
    assert data.rigs["bandai-namco"]["joints"] == 21
    # the recovered motion has the build's joint positions (up to the normalising scale)
    layout = FeatureLayout(ds.skeleton.num_joints)
    parts = layout.split(ds[0]["features"].double())
    want = parts["joint_pos"].clone()
    want[..., 0] += parts["root_pos"][:, None, 0]
    want[..., 2] += parts["root_pos"][:, None, 2]
    m = data.motion(0)
    scale = data.rigs["bandai-namco"]["scale"]
    assert scale == 1.0 / rest_extent(ds.skeleton)
    assert torch.allclose(m.positions / scale, want, atol=1e-4)
    train = MultiRigData(manifest, split="train")
    assert 0 < len(train) < len(data) and all(r["split"] == "train" for r in train.clips)
    assert main(["data", "stats", str(manifest)]) == 0
    out = capsys.readouterr().out
    assert "bandai-namco" in out and "1 rigs (21-21 joints)" in out
