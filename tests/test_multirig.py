"""Multi-rig training sets: motion hashes, a Bandai Namco build joined through a manifest, stats."""

from __future__ import annotations

import torch

from kinema.cli import main
from kinema.data.dataset import MotionDataset
from kinema.data.motion_cache import motion_hash, rest_extent
from kinema.data.multirig import MultiRigData, write_manifest
from kinema.motion.core import Motion
from kinema.representation.layout import FeatureLayout


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


def _chain(joints: int, seed: int, frames: int = 10) -> Motion:
    """A random chain motion (metres, 20 fps) on a ``joints``-joint skeleton named by its size."""
    from kinema.geometry.rotations import quat_normalize
    from kinema.skeleton import Skeleton

    g = torch.Generator().manual_seed(seed)
    skel = Skeleton([f"j{i}" for i in range(joints)], [-1] + list(range(joints - 1)), [[0.0, 0.2, 0.0]] * joints)
    rot = quat_normalize(torch.randn(frames, joints, 4, generator=g, dtype=torch.float64))
    return Motion(skel, 20.0, torch.zeros(frames, 3, dtype=torch.float64), rot)


def test_assemble_rigs_dedup_and_prop_rigs_stay_in_train(tmp_path) -> None:
    from pathlib import Path

    from kinema.data.multirig_build import Description, assemble
    from kinema.data.sources import SourceFile

    files = [SourceFile(Path(f"{j}.bvh"), f"r{j}.bvh", "bvh", {"a": _chain(j, j)}) for j in range(2, 9)]
    files.append(SourceFile(Path("copy.bvh"), "copy.bvh", "bvh", {"a": _chain(5, 5)}))  # same data as r5
    # counted like the others, rig "zz-lever" would be the val rig (checked): the prop rule keeps it in train
    files.append(SourceFile(Path("zz-lever.bvh"), "zz-lever.bvh", "bvh", {"on": _chain(9, 1)}))

    def describe(f, name, motion, travel):
        return Description([f"{f.rel} moves."], flags=["prop"] if f.rel == "zz-lever.bvh" else [])

    asm = assemble(files, 20.0, describe)
    w = asm.writer
    assert asm.duplicates == 1 and len(w.clips) == 8 and asm.total_clips == 9
    assert next(r for r in w.clips if r["path"] == "r5.bvh")["duplicates"] == ["copy.bvh"]
    assert len(w.rigs) == 8 and w.rigs["r5"]["files"] == ["r5.bvh", "copy.bvh"]
    assert w.rigs["zz-lever"]["split"] == "train"  # props are never the held-out rig
    assert {"val", "test"} <= {r["split"] for r in w.rigs.values()}
    for rec in w.clips:
        assert rec["split"] == w.rigs[rec["rig"]]["split"]
