"""`kinema data build folder`: your own BVH files with sidecar captions, units, dedup, rigs, CLI errors."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from kinema.cli import main
from kinema.data.dataset import MotionDataset
from kinema.data.folder import build_folder
from kinema.data.motion_cache import MotionCache
from kinema.data.multirig import MultiRigData, write_manifest
from kinema.data.synthetic import animate, bvh_text
from kinema.errors import DataError
from kinema.geometry.rotations import axis_angle_to_quat
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton


def _human(path: Path, content: str, seed: int) -> None:
    """A synthetic human clip (centimetres, 30 fps, Bandai's 22 joints) as a BVH file."""
    path.write_text(bvh_text(animate(content, "normal", 1.5, np.random.default_rng(seed))))


def _creature(path: Path, joints: int, phase: float, length_m: float = 0.6) -> None:
    """A swimming chain of ``joints`` joints (metres), written with kinema's BVH writer."""
    names = [f"seg{j}" for j in range(joints)]
    offsets = [[0.0, 0.3, 0.0]] + [[0.0, 0.0, -length_m / (joints - 1)]] * (joints - 1)
    skel = Skeleton(names, [-1] + list(range(joints - 1)), offsets, name=path.stem)
    t = torch.arange(30, dtype=torch.float64) / 30.0
    angle = 0.4 * torch.sin(2 * math.pi * t[:, None] + phase + torch.arange(joints)[None])
    aa = torch.zeros(30, joints, 3, dtype=torch.float64)
    aa[..., 1] = angle
    Motion(skel, 30.0, torch.zeros(30, 3, dtype=torch.float64), axis_angle_to_quat(aa)).save(path)


@pytest.fixture()
def human_folder(tmp_path) -> Path:
    """Four human clips captioned by each sidecar kind, plus an exact copy of one of them."""
    root = tmp_path / "mine"
    (root / "sub").mkdir(parents=True)
    _human(root / "walk.bvh", "walk", 0)
    _human(root / "run.bvh", "run", 1)
    _human(root / "sub" / "wave.bvh", "wave-left-hand", 2)
    _human(root / "bow.bvh", "bow", 3)
    shutil.copy(root / "walk.bvh", root / "walk_copy.bvh")
    (root / "walk.txt").write_text("A person walks.\n\nSomeone walks forward.\n")
    (root / "captions.csv").write_text("file,caption\nrun.bvh,A person runs.\nrun.bvh,Someone jogs.\n")
    (root / "captions.jsonl").write_text(
        '{"file": "sub/wave.bvh", "captions": ["A person waves."]}\n{"file": "bow.bvh", "caption": "A bow."}\n'
        '{"file": "walk_copy.bvh", "caption": "Copy."}\n{"file": "typo.bvh", "caption": "Nobody."}\n'
    )
    return root


def test_folder_build_human(human_folder, tmp_path) -> None:
    out = tmp_path / "cache"
    meta, messages = build_folder(human_folder, out, fps=20, progress=False)
    assert messages[0].startswith("detected centimetres from a ") and "pass --units m to override" in messages[0]
    assert "caption entry matches no clip: typo.bvh" in messages
    c = meta["counts"]
    assert (c["files"], c["source_clips"], c["duplicates_dropped"], c["clips"], c["rigs"]) == (5, 5, 1, 4, 1)
    cache = MotionCache(out)
    by_path = {r["path"]: r for r in cache.clips}
    assert by_path["walk.bvh"]["captions"] == ["A person walks.", "Someone walks forward."]  # sidecar .txt
    assert by_path["run.bvh"]["captions"] == ["A person runs.", "Someone jogs."]  # captions.csv
    assert by_path["sub/wave.bvh"]["captions"] == ["A person waves."]  # captions.jsonl
    assert by_path["walk.bvh"]["duplicates"] == ["walk_copy.bvh"]  # the exact copy is dropped
    rig = cache.rigs[by_path["walk.bvh"]["rig"]]
    assert rig["joints"] == 22 and len(rig["files"]) == 5 and rig["names"][1] == "Hips"
    m = cache.motion(0)
    assert m.fps == 20 and m.num_joints == 22
    extent = m.positions[0].max(0).values - m.positions[0].min(0).values
    assert 0.5 < float(extent.max()) < 1.5  # normalised: about one unit across
    scale = json.loads((out / "skeletons.json").read_text())["walk.bvh"]["scale"]
    assert 0.3 < scale < 1.0  # metres -> normalised for a ~1.3-1.7 m tall human
    ds = MotionDataset(out, "all")  # one human rig: the flat trainer's files are there too
    assert ds.skeleton.names[0] == "Hips" and ds.layout.num_joints == 21 and len(ds) == 4


def test_units_override_and_train(human_folder, tmp_path) -> None:
    out = tmp_path / "cache_m"
    _, messages = build_folder(human_folder, out, fps=20, units="cm", progress=False)
    assert not any(m.startswith("detected") for m in messages)  # units given: nothing detected
    # given as metres, a 170-unit human is 170 m tall: the stored factor says so
    build_folder(human_folder, tmp_path / "as_m", fps=20, units="m", progress=False)
    s_cm = json.loads((out / "skeletons.json").read_text())["walk.bvh"]["scale"]
    s_m = json.loads((tmp_path / "as_m" / "skeletons.json").read_text())["walk.bvh"]["scale"]
    assert s_cm == pytest.approx(100 * s_m)
    run = tmp_path / "run"
    args = ["train", "--data", str(out), "--out", str(run), "--config", "tiny", "--steps", "2", "--batch-size", "2"]
    assert main(args + ["--text-encoder", "hash-test-32", "--no-progress"]) == 0
    assert any(run.glob("ckpt-*"))


def test_multi_rig_folder(tmp_path, capsys) -> None:
    root = tmp_path / "zoo"
    root.mkdir()
    _human(root / "walk.bvh", "walk", 0)
    for i, j in enumerate((3, 4, 5, 6)):
        _creature(root / f"eel{j}.bvh", j, phase=float(i))
    _creature(root / "eel4_twin.bvh", 4, phase=7.0)  # same skeleton as eel4: one rig, two files
    for p in root.glob("*.bvh"):
        p.with_suffix(".txt").write_text(f"A {p.stem} moves.\n")
    out = tmp_path / "zoo_cache"
    meta, messages = build_folder(root, out, fps=20, progress=False)
    assert messages[0].startswith("detected metres from a 0.583-unit-long first frame (eel3.bvh, 5 files)")
    assert messages[1].startswith("detected centimetres") and "(walk.bvh)" in messages[1]
    assert meta["counts"]["rigs"] == 5 and not meta["trainable"]
    cache = MotionCache(out)
    assert sorted(r["joints"] for r in cache.rigs.values()) == [3, 4, 5, 6, 22]
    eel4 = next(r for r in cache.rigs.values() if r["joints"] == 4)
    assert eel4["files"] == ["eel4.bvh", "eel4_twin.bvh"]
    splits = {r["rig"]: r["split"] for r in cache.rigs.values()}
    assert {"val", "test"} <= set(splits.values())
    for rec in cache.clips:  # whole rigs are held out
        assert rec["split"] == splits[rec["rig"]]
    with pytest.raises(DataError, match="different skeletons; the current trainer needs every clip on one skeleton"):
        MotionDataset(out)
    assert main(["train", "--data", str(out), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "multi-rig motion cache" in err
    assert "kinema train-anyrig" in err and "next issue" not in err  # issue 36: the trainer exists
    assert main(["data", "stats", str(out)]) == 0
    table = capsys.readouterr().out
    assert "5 rigs (3-22 joints)" in table and "eel4" in table
    held = sorted(r for r, split in splits.items() if split != "train")
    pinned = tmp_path / "zoo_pinned"
    assert main(["data", "build", "folder", "--root", str(root), "--out", str(pinned), "--quiet",
                 "--train-rigs", held[0]]) == 0
    capsys.readouterr()
    again = {r["rig"]: r["split"] for r in MotionCache(pinned).rigs.values()}
    assert again == splits | {held[0]: "train"}
    assert f"kept in train: {held[0]}" in json.loads((pinned / "meta.json").read_text())["split_rule"]
    assert main(["data", "build", "folder", "--root", str(root), "--out", str(tmp_path / "bad"), "--quiet",
                 "--train-rigs", "dragon"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("--train-rigs dragon: no such rig in this build (rigs: eel3, eel4, eel5, eel6, walk)")
    assert not (tmp_path / "bad" / "meta.json").exists()


def test_manifest_joins_builds(human_folder, tmp_path) -> None:
    a = tmp_path / "a"
    build_folder(human_folder, a, fps=20, progress=False)
    manifest = tmp_path / "both.json"
    write_manifest(manifest, [a, a])
    with pytest.raises(DataError, match="lists no datasets"):
        manifest.write_text('{"format": "kinema-manifest", "version": 1, "datasets": []}')
        MultiRigData(manifest)
    write_manifest(manifest, [a])
    data = MultiRigData(manifest)
    assert len(data) == 4 and data.clips[0]["dataset"] == "folder"
    direct = MotionCache(a)
    assert torch.equal(data.motion(0).local_rotations, direct.motion(0).local_rotations)


def test_uncaptioned_error_and_skip(human_folder, tmp_path, capsys) -> None:
    (human_folder / "captions.jsonl").unlink()
    with pytest.raises(DataError, match=r"2 clip\(s\) have no captions \(bow.bvh, sub/wave.bvh\)"):
        build_folder(human_folder, tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()  # nothing half-written
    meta, messages = build_folder(human_folder, tmp_path / "y", skip_uncaptioned=True, progress=False)
    assert "skipped (no captions): bow.bvh" in messages and meta["counts"]["clips"] == 2
    assert main(["data", "build", "folder", "--root", str(human_folder), "--out", str(tmp_path / "z"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--skip-uncaptioned" in err


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        (lambda root: None, "folder does not exist"),
        (lambda root: root.mkdir(), "no motion files (.bvh, .bvh.gz, .glb) found"),
        (lambda root: (root.mkdir(), (root / "captions.csv").write_text("name,text\n")), "no motion files"),
    ],
)
def test_cli_errors_exit_2_with_one_line(tmp_path, capsys, setup, message) -> None:
    root = tmp_path / "data"
    setup(root)
    assert main(["data", "build", "folder", "--root", str(root), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def test_bad_caption_files(tmp_path) -> None:
    root = tmp_path / "d"
    root.mkdir()
    _creature(root / "eel.bvh", 3, 0.0)
    (root / "captions.csv").write_text("name,text\neel.bvh,An eel.\n")
    with pytest.raises(DataError, match=r"captions.csv: expected a header with columns 'file' and 'caption'"):
        build_folder(root, tmp_path / "o", progress=False)
    (root / "captions.csv").unlink()
    (root / "captions.jsonl").write_text('{"file": "eel.bvh", "captions": ["An eel."]}\n{broken\n')
    with pytest.raises(DataError, match=r"captions.jsonl:2: not JSON"):
        build_folder(root, tmp_path / "o", progress=False)
    (root / "captions.jsonl").write_text('{"file": "eel.bvh", "captions": []}\n')
    (root / "eel.txt").write_text("\n  \n")  # empty captions count as none
    with pytest.raises(DataError, match=r"1 clip\(s\) have no captions \(eel.bvh\)"):
        build_folder(root, tmp_path / "o", progress=False)
