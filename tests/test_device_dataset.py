"""scripts/device_dataset.py: a build packed small enough to travel to a GPU machine, and rebuilt there."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from kinema.data.dataset import MotionDataset
from kinema.representation.layout import FeatureLayout

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts/device_dataset.py"


def _run(*args, cwd: Path) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return proc


@pytest.fixture(scope="module")
def rebuilt(tiny_data, tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("device_dataset")
    pack = tmp / "tiny.pack"
    _run("pack", tiny_data, pack, "--splits", "train", "val", "test", cwd=tmp)
    assert pack.stat().st_size < 0.25 * (tiny_data / "features.safetensors").stat().st_size
    _run("unpack", pack, tmp / "rebuilt", cwd=tmp)
    return tmp / "rebuilt"


def _by_clip(folder: Path) -> tuple[dict, dict]:
    ds = MotionDataset(folder, "all")
    items = [ds[i] for i in range(len(ds))]
    return {it["clip"]["clip_id"]: it["clip"] for it in items}, {it["clip"]["clip_id"]: it["features"] for it in items}


def test_rebuilt_features_match_the_build(tiny_data, rebuilt):
    """Every clip comes back with its record and its features up to the packing's quantisation: pelvis
    0.1 mm, quaternion components 1.2e-4. Mirrored copies are remade by ``Motion.mirror`` on the build's
    shared skeleton, so their positions match but a bone's twist may not (the build mirrors each clip on
    its own skeleton): their rotations are not compared."""
    orig_clips, orig = _by_clip(tiny_data)
    new_clips, new = _by_clip(rebuilt)
    assert orig_clips.keys() == new_clips.keys()
    layout = FeatureLayout(json.loads((tiny_data / "meta.json").read_text())["layout"]["num_joints"])
    for clip_id, a in orig.items():
        assert {k: v for k, v in new_clips[clip_id].items() if k != "start"} == \
               {k: v for k, v in orig_clips[clip_id].items() if k != "start"}
        pa, pb = layout.split(a), layout.split(new[clip_id])
        assert (pa["root_pos"] - pb["root_pos"]).abs().max() < 2e-4, clip_id
        assert (pa["joint_pos"] - pb["joint_pos"]).abs().max() < 2e-3, clip_id  # metres
        assert (pa["joint_vel"] - pb["joint_vel"]).abs().max() < 0.05, clip_id  # m/s
        assert torch.equal(pa["contacts"], pb["contacts"]), clip_id
        if not orig_clips[clip_id]["mirrored"]:
            assert (pa["joint_rot"] - pb["joint_rot"]).abs().max() < 2e-3, clip_id


def test_the_rebuild_says_which_splits_it_holds(tiny_data, tmp_path):
    _run("pack", tiny_data, tmp_path / "train.pack", cwd=tmp_path)  # default: the train split only
    _run("unpack", tmp_path / "train.pack", tmp_path / "train", cwd=tmp_path)
    meta = json.loads((tmp_path / "train" / "meta.json").read_text())
    assert meta["packed_splits"] == ["train"]
    splits = {c["split"] for c in json.loads((tmp_path / "train" / "clips.json").read_text())}
    assert splits == {"train"}
    assert json.loads((tmp_path / "train" / "stats.json").read_text()) == \
           json.loads((tiny_data / "stats.json").read_text())  # the build's statistics travel unchanged
