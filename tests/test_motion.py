"""Motion: FK against an independent computation, time edits, mirroring, pruning, npz round trip."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_normalize
from kinema.io import load_motion
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton
from tests.test_skeleton import SCHEMES, humanoid


def random_motion(T=40, seed=0, scheme="bandai", dtype=torch.float64) -> Motion:
    g = torch.Generator().manual_seed(seed)
    skel = humanoid(SCHEMES[scheme])
    q = torch.randn(T, skel.num_joints, 4, generator=g, dtype=dtype) * 0.3
    q[..., 0] += 1.0
    root = torch.cumsum(torch.randn(T, 3, generator=g, dtype=dtype) * 0.02, 0) + torch.tensor([0, 0.9, 0])
    return Motion(skel, 30, root, quat_normalize(q))


def scipy_fk(motion: Motion) -> np.ndarray:
    """Joint positions computed with scipy rotations and an explicit loop (independent of kinema FK)."""
    q = motion.local_rotations.numpy()
    offsets = motion.skeleton.offsets.numpy()
    T, J = q.shape[:2]
    out = np.zeros((T, J, 3))
    for t in range(T):
        glob = [None] * J
        for j, p in enumerate(motion.skeleton.parents):
            r = Rotation.from_quat(q[t, j][[1, 2, 3, 0]])
            if p < 0:
                glob[j], out[t, j] = r, motion.root_translation[t].numpy()
            else:
                glob[j] = glob[p] * r
                out[t, j] = out[t, p] + glob[p].apply(offsets[j])
    return out


def test_fk_matches_independent_computation():
    m = random_motion(T=5)
    assert np.allclose(m.positions.numpy(), scipy_fk(m), atol=1e-10)


def test_from_global_inverts_fk():
    m = random_motion()
    again = Motion.from_global(m.skeleton, m.fps, m.root_translation, m.global_rotations)
    assert torch.allclose(again.positions, m.positions, atol=1e-10)


def test_crop_and_concatenate_round_trip():
    m = random_motion(T=30)
    parts = m.crop(0, 12).concatenate(m.crop(12))
    assert torch.equal(parts.local_rotations, m.local_rotations)
    assert m.crop(-5).num_frames == 5
    with pytest.raises(KinemaError, match="empty"):
        m.crop(10, 10)
    other_fps = Motion(m.skeleton, 20, m.root_translation, m.local_rotations)
    with pytest.raises(KinemaError, match="resample"):
        m.concatenate(other_fps)


def test_resample_keeps_frames_on_the_common_grid_and_interpolates_between():
    m = random_motion(T=31)  # 30 fps, 1 s
    down = m.resample(10)
    assert down.num_frames == 11 and down.fps == 10
    assert torch.allclose(down.positions, m.positions[::3], atol=1e-9)
    up = down.resample(30)
    assert up.num_frames == 31
    assert torch.allclose(up.positions[::3], down.positions, atol=1e-9)
    # halfway frames lie between their neighbours (slerp of a smooth motion stays close)
    assert (up.positions[1] - down.positions[0]).norm(dim=-1).max() <= (
        (down.positions[1] - down.positions[0]).norm(dim=-1).max() + 1e-6
    )


def test_mirror_reflects_positions_and_is_an_involution():
    m = random_motion(scheme="mixamo")
    mm = m.mirror()
    mmap = list(m.skeleton.mirror_map)
    reflect = torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    assert torch.allclose(mm.positions[:, mmap] * reflect, m.positions, atol=1e-9)
    back = mm.mirror()
    assert torch.allclose(back.positions, m.positions, atol=1e-9)
    assert torch.allclose(back.global_rotations.abs(), m.global_rotations.abs(), atol=1e-9)


def test_prune_static_joint_keeps_positions():
    m = random_motion()
    skel = m.skeleton
    # freeze the spine so pruning it is lossless
    q = m.local_rotations.clone()
    q[:, skel.index("Spine")] = q[0, skel.index("Spine")]
    m = Motion(skel, m.fps, m.root_translation, q)
    pruned = m.prune(["Spine"])
    assert "Spine" not in pruned.skeleton.names
    keep = [j for j, n in enumerate(skel.names) if n != "Spine"]
    assert torch.allclose(pruned.positions, m.positions[:, keep], atol=1e-9)
    assert torch.allclose(pruned.global_rotations.abs(), m.global_rotations[:, keep].abs(), atol=1e-9)


def test_prune_moving_joint_warns():
    m = random_motion()
    with pytest.warns(UserWarning, match="moves kept joints"):
        m.prune(["Spine"])


def test_npz_round_trip_and_contract(tmp_path):
    m = random_motion(dtype=torch.float32)
    m.foot_contacts = torch.zeros(m.num_frames, 4)
    path = m.save(tmp_path / "clip.npz")
    with np.load(path, allow_pickle=False) as data:
        assert data["positions"].shape == (m.num_frames, m.num_joints, 3)
        assert data["local_quats"].shape == (m.num_frames, m.num_joints, 4)
        assert list(data["joint_names"]) == list(m.skeleton.names)
        assert float(data["fps"]) == 30.0
    again = load_motion(path)
    assert torch.allclose(again.positions, m.positions, atol=1e-5)
    assert again.skeleton.rest_rotations is None


def test_npz_keeps_the_skeletons_rest_rotations(tmp_path):
    """The default model's skeleton carries its standing rest pose; an npz without it made `kinema retarget
    walk.npz --rig character` measure every bone from Bandai's +X rest (legs turned 180 degrees about
    themselves on a skinned character). A zero-length rest quaternion is a one-line error."""
    m = random_motion(dtype=torch.float32)
    rest = torch.nn.functional.normalize(torch.randn(m.num_joints, 4, dtype=torch.float64), dim=-1)
    skel = Skeleton(m.skeleton.names, m.skeleton.parents, m.skeleton.offsets, rest)
    m = Motion(skel, m.fps, m.root_translation, m.local_rotations)
    again = load_motion(m.save(tmp_path / "clip.npz"))
    assert torch.allclose(again.skeleton.rest_rotations, skel.rest_rotations)
    assert torch.allclose(again.positions, m.positions, atol=1e-5)
    with np.load(tmp_path / "clip.npz", allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["rest_rotations"][2] = 0.0
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(KinemaError, match="'rest_rotations' holds 1 quaternion"):
        load_motion(tmp_path / "bad.npz")


def test_invalid_motion_and_files(tmp_path):
    m = random_motion()
    with pytest.raises(KinemaError, match="joints"):
        Motion(m.skeleton, 30, m.root_translation, m.local_rotations[:, :3])
    with pytest.raises(KinemaError, match="fps"):
        Motion(m.skeleton, 0, m.root_translation, m.local_rotations)
    with pytest.raises(KinemaError, match="unknown motion format"):
        m.save(tmp_path / "x.fbx")
    bad = Motion(m.skeleton, 30, m.root_translation, m.local_rotations.clone())
    bad.local_rotations[3, 2, 0] = float("nan")
    with pytest.raises(KinemaError, match="NaN"):
        bad.save(tmp_path / "bad.npz")
    assert not (tmp_path / "bad.npz").exists()
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(KinemaError, match="junk.npz"):
        load_motion(tmp_path / "junk.npz")


def test_rebase_rest_pose_keeps_positions_and_writes_a_clean_rest(tmp_path):
    from kinema.motion.rest import clean_skeleton, rebase_rest_pose
    from kinema.skeleton import Skeleton

    m = random_motion(T=10)
    rest = m.local_rotations[3]
    skel = Skeleton(m.skeleton.names, m.skeleton.parents, m.skeleton.offsets, rest_rotations=rest)
    m = Motion(skel, m.fps, m.root_translation, m.local_rotations)
    r = rebase_rest_pose(m)
    assert torch.allclose(r.positions, m.positions, atol=1e-9)
    # the clean skeleton's identity pose is the chosen rest pose (up to where the root stands)
    clean = clean_skeleton(skel, rest)
    ident = Motion(clean, 30, m.root_translation[3:4], torch.tensor([1.0, 0, 0, 0]).expand(1, skel.num_joints, 4))
    posed = Motion(skel, 30, m.root_translation[3:4], rest[None])
    assert torch.allclose(ident.positions, posed.positions.to(ident.dtype), atol=1e-6)
    back = load_motion(m.save(tmp_path / "clean.bvh"))  # BVH stores joints depth-first: match by name
    order = [back.skeleton.names.index(n) for n in skel.names]
    assert (back.positions[:, order] - m.positions).abs().max() < 1e-4
