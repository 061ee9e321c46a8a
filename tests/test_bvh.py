"""BVH reader/writer: real Bandai Namco clips against an independent scipy forward kinematics,
round trips, text variants and writer safety. Broken files that must fail with file name and line
are tests/test_bvh_errors.py."""

from __future__ import annotations

import gzip
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from kinema.cli import main
from kinema.errors import KinemaError
from kinema.io import bvh
from kinema.io.bvh import BVHData, parse_bvh, read_bvh
from kinema.io.bvh_writer import format_bvh, motion_to_bvh_data, write_bvh
from tests.test_bvh_errors import GOOD


@pytest.fixture(scope="module")
def sample(bandai_root) -> list[Path]:
    """Ten Bandai files spread over the data in use (real, or the synthetic clips: see conftest.py)."""
    files = sorted(bandai_root.glob("*/data/*.bvh.gz"))
    assert files
    return files[:: max(1, len(files) // 10)][:10]


def reference_positions(data: BVHData, scale: float) -> np.ndarray:
    """(T, J, 3) joint positions straight from the raw channels with scipy, written independently of
    kinema: position channels replace the offset axis by axis, rotations are intrinsic Euler angles
    in the listed order (uppercase scipy sequence)."""
    T, J = data.num_frames, data.num_joints
    glob_rot: list[Rotation] = []
    pos = np.zeros((T, J, 3))
    col = 0
    for j, chans in enumerate(data.channels):
        trans = np.tile(data.offsets[j] * scale, (T, 1))
        rot_axes, rot_cols = "", []
        for k, ch in enumerate(chans):
            axis = "XYZ".index(ch[0])
            if ch.endswith("position"):
                trans[:, axis] = data.values[:, col + k] * scale
            else:
                rot_axes += ch[0]
                rot_cols.append(col + k)
        col += len(chans)
        local = (
            Rotation.from_euler(rot_axes, data.values[:, rot_cols], degrees=True) if rot_axes else Rotation.identity(T)
        )
        p = data.parents[j]
        if p < 0:
            glob_rot.append(local)
            pos[:, j] = trans
        else:
            glob_rot.append(glob_rot[p] * local)
            pos[:, j] = pos[:, p] + glob_rot[p].apply(trans)
    return pos


# ----------------------------------------------------------------------------- real data


def test_parse_real_sample(sample):
    for path in sample:
        data = parse_bvh(path)
        assert data.num_joints == 22 and data.names[0] == "joint_Root" and data.parents[0] == -1
        assert all(len(c) == 6 for c in data.channels)
        assert data.channels[1] == [
            "Xposition",
            "Yposition",
            "Zposition",
            "Zrotation",
            "Xrotation",
            "Yrotation",
        ]
        assert data.values.shape == (data.num_frames, 132) and data.num_frames > 0
        assert data.frame_time == pytest.approx(1 / 30, rel=1e-4)
        assert len(data.end_sites) == 5 and data.path == str(path)


def test_real_positions_match_independent_fk(sample):
    for path in sample:
        motion = read_bvh(path, scale=0.01)
        ref = reference_positions(parse_bvh(path), 0.01)
        got = motion.positions.numpy()
        assert motion.fps == 30.0 and motion.skeleton.num_joints == 22
        # every joint below the static joint_Root is exact; the root itself carries the hips' motion
        np.testing.assert_allclose(got[:, 1:], ref[:, 1:], atol=1e-5, rtol=0)
        np.testing.assert_allclose(got[0], ref[0], atol=1e-5, rtol=0)
        pruned = motion.prune(["joint_Root"])
        np.testing.assert_allclose(pruned.positions.numpy(), ref[:, 1:], atol=1e-5, rtol=0)


@pytest.mark.parametrize("scale,order,suffix", [(1.0, "ZXY", ".bvh"), (100.0, "XYZ", ".bvh.gz")])
def test_real_round_trip(sample, tmp_path, scale, order, suffix):
    for path in sample[:3]:
        motion = read_bvh(path, scale=0.01)
        out = write_bvh(motion, tmp_path / f"clip{suffix}", scale=scale, order=order)
        again = read_bvh(out, scale=1 / scale)
        assert again.skeleton.names == motion.skeleton.names and again.fps == motion.fps
        assert (again.positions - motion.positions).abs().max() < 1e-4


# ----------------------------------------------------------------------------- synthetic layouts

MIXED = """HIERARCHY
ROOT Pelvis
{
  OFFSET 1 2 3
  CHANNELS 6 Xrotation Yrotation Zrotation Xposition Yposition Zposition
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Yrotation Xrotation Zrotation
    JOINT Neck
    {
      OFFSET 0 8 1
      CHANNELS 0
      JOINT Head
      {
        OFFSET 0 5 0
        CHANNELS 2 Zrotation Xrotation
        End Site
        {
          OFFSET 0 3 0
        }
      }
    }
    JOINT Arm
    {
      OFFSET 4 0 0
      CHANNELS 6 Xposition Yposition Zposition Yrotation Zrotation Xrotation
      JOINT Hand
      {
        OFFSET 3 0 0
        CHANNELS 1 Zrotation
      }
    }
  }
  JOINT Leg
  {
    OFFSET -2 -1 0
    CHANNELS 3 Xposition Zrotation Yposition
  }
}
MOTION
"""
MIXED_POSITION_COLUMNS = {11: 4.5, 12: 0.5, 13: -0.25, 18: -2.5, 20: -1.5}  # constant per column


def mixed_text(frames: int = 7, seed: int = 0, moving_arm: bool = False) -> str:
    rng = np.random.default_rng(seed)
    values = rng.uniform(-170, 170, size=(frames, 21))
    values[:, 3:6] = rng.uniform(-50, 50, size=(frames, 3))  # root position
    for col, v in MIXED_POSITION_COLUMNS.items():
        values[:, col] = v
    if moving_arm:
        values[:, 11] += np.linspace(0, 2, frames)
    rows = "\n".join(" ".join(f"{x:.9g}" for x in r) for r in values)
    return f"{MIXED}Frames: {frames}\nFrame Time: 0.008333\n{rows}\n"


def test_mixed_layout_matches_independent_fk(tmp_path):
    data = parse_bvh(mixed_text())
    assert data.channels[3] == ["Zrotation", "Xrotation"] and data.channels[2] == []
    assert set(data.end_sites) == {3} and data.column_starts == [0, 6, 9, 9, 11, 17, 18]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        motion = bvh.bvh_data_to_motion(data, scale=0.01)
    assert motion.fps == 120.0
    np.testing.assert_allclose(motion.positions.numpy(), reference_positions(data, 0.01), atol=1e-9)
    assert motion.skeleton.end_sites == {3: pytest.approx((0.0, 0.03, 0.0))}
    for order in ("XYZ", "YXZ", "ZYX"):
        out = write_bvh(motion, tmp_path / f"mixed_{order}.bvh", scale=100.0, order=order)
        again = read_bvh(out, scale=0.01)
        assert parse_bvh(out).channels[1] == [f"{a}rotation" for a in order]
        assert (again.positions - motion.positions).abs().max() < 1e-4


STATIC_ROOT = """HIERARCHY
ROOT Origin
{
  OFFSET 1 0 2
  CHANNELS 3 Yrotation Xrotation Zrotation
  JOINT Hips
  {
    OFFSET 5 5 5
    CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
    JOINT Knee
    {
      OFFSET 0 -4 0
      CHANNELS 3 Xrotation Yrotation Zrotation
      End Site { OFFSET 0 -4 0 }
    }
    JOINT Chest
    {
      OFFSET 0 3 0
      CHANNELS 3 Zrotation Yrotation Xrotation
    }
  }
}
MOTION
"""


def test_static_root_carries_child_translation():
    """A static root (constant rotation here) whose only child moves: every joint below it is exact."""
    rng = np.random.default_rng(1)
    values = rng.uniform(-90, 90, size=(6, 15))
    values[:, :3] = [30.0, -20.0, 10.0]
    rows = "\n".join(" ".join(f"{x:.9g}" for x in r) for r in values)
    data = parse_bvh(f"{STATIC_ROOT}Frames: 6\nFrame Time: 0.04\n{rows}\n")
    assert data.end_sites.keys() == {2}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        motion = bvh.bvh_data_to_motion(data, scale=0.01)
    ref = reference_positions(data, 0.01)
    assert motion.fps == 25.0
    np.testing.assert_allclose(motion.positions.numpy()[:, 1:], ref[:, 1:], atol=1e-9)
    np.testing.assert_allclose(motion.positions.numpy()[0], ref[0], atol=1e-9)


def test_moving_position_channels_are_kept(tmp_path):
    """A non-root joint whose position channels move keeps them per frame (Motion.local_translations):
    forward kinematics matches the file, and written BVH carries them again."""
    data = parse_bvh(mixed_text(moving_arm=True), source_name="arm.bvh")
    motion = bvh.bvh_data_to_motion(data, scale=0.01)
    assert motion.local_translations is not None
    np.testing.assert_allclose(motion.positions.numpy(), reference_positions(data, 0.01), atol=1e-9)
    again = read_bvh(write_bvh(motion, tmp_path / "arm.bvh"))
    assert (again.positions - motion.positions).abs().max() < 1e-5


def test_raw_format_round_trip():
    data = parse_bvh(mixed_text())
    again = parse_bvh(format_bvh(data, precision=9))
    assert again.names == data.names and again.parents == data.parents and again.channels == data.channels
    np.testing.assert_allclose(again.values, data.values, atol=1e-8)
    np.testing.assert_allclose(again.offsets, data.offsets)


def test_text_variants_parse_identically(tmp_path):
    base = mixed_text()
    ref = parse_bvh(base)
    lines = base.split("\n")
    frame_lines = [k for k, ln in enumerate(lines) if ln and ln[0] in "-0123456789"]
    sci = list(lines)
    for k in frame_lines:
        sci[k] = "  \t".join(f"{float(x):.12e}" for x in lines[k].split()) + "   "
    variants = {
        "crlf": base.replace("\n", "\r\n"),
        "tabs": base.replace("  ", "\t").replace(" ", " \t "),
        "scientific": "\n".join(sci) + "\n\n\n",
        "cr_only": base.replace("\n", "\r"),
        "glued_braces": base.replace("ROOT Pelvis\n{", "ROOT Pelvis {"),
    }
    (tmp_path / "g.bvh.gz").write_bytes(gzip.compress(base.encode()))
    (tmp_path / "p.bvh").write_text(base)
    parsed = {k: parse_bvh(v) for k, v in variants.items()}
    parsed["gzip"] = parse_bvh(tmp_path / "g.bvh.gz")
    parsed["path_str"] = parse_bvh(str(tmp_path / "p.bvh"))
    parsed["bytes"] = parse_bvh(base.encode())
    for key, data in parsed.items():
        assert data.names == ref.names and data.channels == ref.channels, key
        np.testing.assert_allclose(data.values, ref.values, rtol=1e-12, err_msg=key)
        np.testing.assert_array_equal(data.offsets, ref.offsets)
        assert data.frame_time == ref.frame_time


# ----------------------------------------------------------------------------- writer safety


def test_writer_leaves_no_partial_file(tmp_path):
    motion = bvh.bvh_data_to_motion(parse_bvh(GOOD))
    target = tmp_path / "out.bvh"
    target.write_text("previous content")
    bad = motion.to(torch.float64)
    bad.local_rotations = bad.local_rotations.clone()
    bad.local_rotations[1, 1, 0] = float("nan")
    for kwargs in ({}, {"order": "XXY"}, {"scale": 0.0}):
        with pytest.raises(KinemaError):
            write_bvh(bad if not kwargs else motion, target, **kwargs)
    assert target.read_text() == "previous content" and os.listdir(tmp_path) == ["out.bvh"]
    write_bvh(motion, tmp_path / "sub" / "ok.bvh.gz")
    assert sorted(os.listdir(tmp_path / "sub")) == ["ok.bvh.gz"]
    text = gzip.decompress((tmp_path / "sub" / "ok.bvh.gz").read_bytes()).decode()
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in text
    assert "End Site" in text and "Frame Time: 0.03333333333" in text
    raw = motion_to_bvh_data(motion, order="YXZ")
    assert raw.channels[1] == ["Yrotation", "Xrotation", "Zrotation"] and raw.values.shape == (3, 9)


# ----------------------------------------------------------------------------- bench CLI


def test_bench_bvh_cli(tmp_path, capsys):
    for k in range(3):
        (tmp_path / "d" / "data").mkdir(parents=True, exist_ok=True)
        (tmp_path / "d" / "data" / f"c{k}.bvh.gz").write_bytes(gzip.compress(GOOD.encode()))
    threads = str(torch.get_num_threads())  # keep this process's torch setting unchanged
    assert main(["bench", "bvh", "--root", str(tmp_path), "--limit", "2", "--threads", threads]) == 0
    out = capsys.readouterr().out
    assert "raw parse" in out and "to Motion" in out and "files/s" in out
    assert main(["bench", "bvh", "--root", str(tmp_path / "empty")]) == 2


def test_root_follows_child_or_stays(tmp_path):
    """A root with one child whose translation moves: by default (Bandai) the root follows that child;
    root_follows_child=False keeps every joint, the root included, where the file puts it."""
    import torch

    from kinema.motion.core import Motion
    from kinema.skeleton import Skeleton

    sk = Skeleton(["Base", "Top"], [-1, 0], [[0, 0, 0], [0, 0.5, 0]])
    T = 6
    trans = sk.offsets.float().expand(T, -1, -1).clone()
    trans[:, 1, 1] += torch.linspace(0, 1, T)  # the top slides up 1 m; the base stays
    rots = torch.zeros(T, 2, 4)
    rots[..., 0] = 1
    motion = Motion(sk, 30, torch.zeros(T, 3), rots, None, trans)
    path = write_bvh(motion, tmp_path / "slide.bvh")
    bandai = read_bvh(path)
    assert (bandai.positions[:, 1] - motion.positions[:, 1]).abs().max() < 1e-5  # the top is exact
    assert (bandai.positions[:, 0] - motion.positions[:, 0]).abs().max() > 0.9  # the base follows it
    exact = read_bvh(path, root_follows_child=False)
    assert (exact.positions - motion.positions).abs().max() < 1e-5
