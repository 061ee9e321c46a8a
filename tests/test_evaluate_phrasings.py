"""Prompts in other words (kinema.evaluate.phrasings): the measures on known motions, and the part of a run."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
import torch

from kinema.data.phrasings import PROBES, heldout_captions
from kinema.evaluate.phrasings import (
    captured_reference,
    content_accuracy,
    heldout_prompt,
    probe_summary,
)
from kinema.evaluate.probe_measures import follows_side, ground_speed, hand_heights, raises_hand, window_speed
from kinema.geometry.rotations import axis_angle_to_quat
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

FPS, T = 20.0, 41
DOCS = Path(__file__).resolve().parents[1] / "docs" / "evaluation.md"


def _body() -> Skeleton:
    """Pelvis at the origin, head 0.7 m up, arms of 0.5 m hanging from shoulders 0.5 m up."""
    names = ["Hips", "Spine", "Head", "LeftShoulder", "LeftHand", "RightShoulder", "RightHand"]
    parents = [-1, 0, 1, 0, 3, 0, 5]
    offsets = [[0, 0, 0], [0, 0.2, 0], [0, 0.5, 0], [0.2, 0.5, 0], [0, -0.5, 0], [-0.2, 0.5, 0], [0, -0.5, 0]]
    return Skeleton(names, parents, offsets, name="body")


def _motion(velocity=(0.0, 0.0), left_up_deg: float = 0.0, right_up_deg: float = 0.0) -> Motion:
    """A motion moving at ``velocity`` (x, z m/s) with a bob in y; each arm swings up to the given angle
    (0 = hanging down, 180 = straight up) at mid-motion and back."""
    t = torch.arange(T, dtype=torch.float64) / FPS
    root = torch.stack([velocity[0] * t, 0.05 * torch.sin(6 * t), velocity[1] * t], dim=-1)
    q = torch.zeros(T, 7, 4, dtype=torch.float64)
    q[..., 0] = 1.0
    swing = torch.sin(math.pi * torch.arange(T, dtype=torch.float64) / (T - 1))  # 0 -> 1 (mid) -> 0
    for joint, deg, sign in ((3, left_up_deg, 1.0), (5, right_up_deg, -1.0)):
        angle = sign * math.radians(deg) * swing
        q[:, joint] = axis_angle_to_quat(torch.stack([torch.zeros(T), torch.zeros(T), angle.float()], -1).double())
    return Motion(_body(), FPS, root, q)


def test_ground_speed_is_start_to_end_distance_over_duration():
    assert ground_speed(_motion((1.2, 0.9))) == pytest.approx(1.5, rel=1e-6)  # 3-4-5: sqrt(1.2^2 + 0.9^2)
    assert ground_speed(_motion((0.0, 0.0))) == pytest.approx(0.0, abs=1e-9)  # the y bob does not count
    assert ground_speed(_motion((-3.0, 0.0))) == pytest.approx(3.0, rel=1e-6)


def test_hand_heights_see_the_raised_hand():
    up = _motion(left_up_deg=180.0)  # left hand to 1.0 m at mid-motion, head at 0.7 m
    named, other = hand_heights(up, "left")
    assert named == pytest.approx(0.3, abs=1e-4) and other == pytest.approx(-0.7, abs=1e-4)
    assert raises_hand(named, other) and not raises_hand(*hand_heights(up, "right"))
    assert follows_side(named, other) and not follows_side(*hand_heights(up, "right"))
    side = _motion(left_up_deg=90.0)  # arm horizontal: hand at shoulder height, below the head
    assert hand_heights(side, "left")[0] == pytest.approx(-0.2, abs=1e-4)
    assert not raises_hand(*hand_heights(side, "left"))
    assert follows_side(*hand_heights(side, "left"))  # 0.5 m above the hanging right hand: the side is right
    assert not follows_side(*hand_heights(_motion(left_up_deg=30.0), "left"))  # a small lift: 0.07 m
    both = _motion(left_up_deg=150.0, right_up_deg=180.0)  # both above the head, the right one higher
    assert raises_hand(*hand_heights(both, "right")) and not raises_hand(*hand_heights(both, "left"))
    assert not follows_side(*hand_heights(both, "right"))  # 0.07 m higher only: both hands went up
    with pytest.raises(ValueError, match="left' or 'right"):
        hand_heights(up, "up")


def test_probe_summary_orders_speed_groups_and_counts_raised_hands():
    records = [
        {"kind": "speed", "group": "1 slow walk", "prompt": "a", "speeds": [0.8, 1.0]},
        {"kind": "speed", "group": "2 walk", "prompt": "b", "speeds": [1.3]},
        {"kind": "speed", "group": "2 walk", "prompt": "c", "speeds": [1.5]},
        {"kind": "speed", "group": "4 sprint", "prompt": "d", "speeds": [3.0, 4.0]},
        {
            "kind": "hand",
            "group": "left",
            "prompt": "e",
            "speeds": [0.0, 0.0, 0.0],
            "raised": [True, False, True],
            "side_followed": [True, True, False],
            "hand_over_head": [0.2, -0.1, 0.3],
            "other_over_head": [-0.5, -0.5, -0.5],
        },
    ]
    s = probe_summary(records)
    assert list(s["speed"]) == ["1 slow walk", "2 walk", "4 sprint"] and s["speed_ordered"] is True
    walk = s["speed"]["2 walk"]
    assert walk["probes"] == 2 and walk["n"] == 2 and walk["mean"] == pytest.approx(1.4)
    assert walk["std"] == pytest.approx(0.1) and (walk["min"], walk["max"]) == (1.3, 1.5)
    (hand,) = s["hand"]
    assert hand["raised_fraction"] == pytest.approx(2 / 3) and hand["side_fraction"] == pytest.approx(2 / 3)
    assert hand["hand_over_head_m"] == pytest.approx(0.4 / 3)
    sprint = s["speed"]["4 sprint"]
    assert sprint["gap"] == pytest.approx(2.1) and sprint["separated"] and "gap" not in s["speed"]["1 slow walk"]
    assert sprint["gap_se"] == pytest.approx(math.sqrt(0.01 / 1 + 0.25 / 1))  # sample variances over n - 1
    assert s["speed_short"] == {} and s["speed_short_ordered"] is None  # no record has short samples
    records[0]["speeds_short"], records[3]["speeds_short"] = [1.0, 1.2], [1.1, 1.3]
    short = probe_summary(records)
    assert list(short["speed_short"]) == ["1 slow walk", "4 sprint"] and short["speed_short_ordered"] is False
    assert short["speed_short"]["4 sprint"]["gap"] == pytest.approx(0.1) and short["speed"] == s["speed"]
    records[3]["speeds"] = [1.2]  # the sprint now slower than the walk
    assert probe_summary(records)["speed_ordered"] is False
    records[3]["speeds"] = [1.45, 1.55]  # faster than the walk by 0.1 m/s, within the noise (se 0.11)
    summary = probe_summary(records)
    assert summary["speed"]["4 sprint"]["gap"] > 0 and summary["speed_ordered"] is False


def test_window_speed_averages_fixed_length_windows():
    steady = _motion((1.2, 0.9))  # 1.5 m/s throughout, 2 s long (41 frames at 20 fps)
    assert window_speed(steady, 1.0) == pytest.approx(1.5, rel=1e-6)
    assert window_speed(steady, 2.0) == pytest.approx(1.5, rel=1e-6)  # one window: the whole motion
    assert window_speed(steady, 2.5) is None  # shorter than a window
    t = torch.arange(T, dtype=torch.float64) / FPS
    root = torch.stack([torch.zeros(T, dtype=torch.float64), torch.zeros(T, dtype=torch.float64), t**2 / 2], -1)
    accel = Motion(_body(), FPS, root, _motion().local_rotations)  # from rest at 1 m/s^2
    assert window_speed(accel, 1.0) == pytest.approx(1.0, abs=0.03)  # windows centred at 0.5, 1.0, 1.5 s


def test_content_accuracy_takes_the_label_of_the_nearest_ground_truth_clip():
    gt = torch.tensor([[1.0, 0.0], [0.9, 0.1], [0.0, 1.0], [-1.0, 0.2]])
    contents = ["walk", "walk", "bow", "run"]
    # nearest other clip: 1, 0, 1 (cosine), 2 -> only the two walks find their own label
    assert content_accuracy(gt, gt, contents, leave_out_self=True) == pytest.approx(0.5)
    assert content_accuracy(gt, gt, contents, leave_out_self=False) == pytest.approx(1.0)
    motions = torch.tensor([[2.0, 0.1], [0.1, 3.0], [0.2, 1.0], [-1.0, 0.1]])  # walk, bow, bow, run by direction
    assert content_accuracy(motions, gt, contents, leave_out_self=False) == pytest.approx(0.75)  # case 2 wants bow
    same = torch.tensor([[1.0, 0.0]] * 4)  # every motion looks like clip 0 (a walk): right for the two walks
    assert content_accuracy(same, gt, contents, leave_out_self=False) == pytest.approx(0.5)


class _Clips:
    def __init__(self, clips):
        self.clips = clips


def test_heldout_prompt_uses_the_clips_content_label_mirrored_included():
    ds = _Clips(
        [{"clip_id": "a", "content": "raise-up-left-hand"}, {"clip_id": "a_m", "content": "raise-up-right-hand"}]
    )
    left, right = heldout_captions("raise-up-left-hand"), heldout_captions("raise-up-right-hand")
    assert heldout_prompt({"clip_id": "a"}, ds, 0) == left[0]
    assert heldout_prompt({"clip_id": "a"}, ds, 1) == left[1] and heldout_prompt({"clip_id": "a"}, ds, 2) == left[0]
    assert heldout_prompt({"clip_id": "a_m"}, ds, 0) == right[0] and "right" in right[0]


def test_captured_reference_measures_the_splits_raise_up_clips(tiny_data):
    from kinema.data.dataset import MotionDataset

    ref = captured_reference(MotionDataset(tiny_data, "all"))
    # the six-clip build holds raise-up-left-hand and raise-up-right-hand, each with its mirror, no locomotion
    assert ref["speed"] == {} and ref["window_speed"] == {} and set(ref["hand"]) == {"left", "right"}
    assert all(v["clips"] == 2 and 0.0 <= v["raised_fraction"] <= 1.0 for v in ref["hand"].values())
    assert all(0.0 <= v["side_fraction"] <= 1.0 for v in ref["hand"].values())


def test_run_suite_phrasings_part_and_report(tiny_checkpoint, tiny_data, tmp_path):
    from kinema.data.dataset import MotionDataset
    from kinema.evaluate.report import format_phrasings_table, write_report
    from kinema.evaluate.retrieval import RetrievalConfig, RetrievalModel
    from kinema.evaluate.runner import run_suite
    from kinema.evaluate.suite import build_suite
    from kinema.generate import load_model

    ds = MotionDataset(tiny_data, "train")
    cfg = RetrievalConfig(width=16, layers=1, heads=2, ff_mult=2, embed_dim=8, text_dim=32, text_hidden=16)
    RetrievalModel(cfg, ds.layout, ds.stats, ds.fps, "hash-test-32").save(tmp_path / "ret")
    cases = build_suite(tiny_data, "train", num_cases=3, seed=0, text_fraction=1.0)
    res = run_suite(
        load_model(tiny_checkpoint),
        cases,
        postprocess_modes=(False,),
        steps=2,
        progress=False,
        retrieval=tmp_path / "ret",
        mm_prompts=0,
        phrasings=1,
    )
    ph = res.data["phrasings"]
    assert ph["samples"] == 1 and [p["prompt"] for p in ph["probes"]] == [p.prompt for p in PROBES]
    assert list(ph["summary"]["speed"]) == ["1 slow walk", "2 walk", "3 jog", "4 sprint"]
    assert isinstance(ph["summary"]["speed_ordered"], bool)
    assert list(ph["summary"]["speed_short"]) == list(ph["summary"]["speed"]) and ph["short_seconds"] == 2.0
    assert all(len(r["speeds_short"]) == 1 for r in ph["probes"] if r["kind"] == "speed")
    for g in ph["summary"]["speed"].values():
        assert g["n"] == g["probes"] >= 2 and 0.0 <= g["min"] <= g["mean"] <= g["max"] < 20.0
    assert len(ph["summary"]["hand"]) == sum(p.kind == "hand" for p in PROBES)
    for h in ph["summary"]["hand"]:
        assert h["raised_fraction"] in (0.0, 1.0) and -3.0 < h["hand_over_head_m"] < 3.0
    assert ph["expected"] is None  # the tiny run folder has no known prompts (kinema export writes them)
    ho = ph["heldout"]
    assert ho["cases"] == 3 and set(ho["rows"]) == {"ground_truth", "template", "heldout"}
    by_id = {r["clip_id"]: r for r in ds.clips}
    for case, pair in zip(cases, ho["pairs"], strict=True):
        assert pair["prompt"] == case["prompt"]
        assert pair["content"] == by_id[case["clip_id"]]["content"]
        assert pair["heldout_prompt"] in heldout_captions(pair["content"])
    for row in ho["rows"].values():
        assert 0.0 <= row["r1_template"] <= row["r3_template"] <= 1.0
        assert 0.0 <= row["r1_heldout"] <= row["r3_heldout"] <= 1.0 and 0.0 <= row["content_acc"] <= 1.0
    assert ho["rows"]["ground_truth"]["fid"] == pytest.approx(0.0, abs=1e-6) and ho["rows"]["heldout"]["fid"] > 0.0
    for row, ranks in ho["ranks"].items():  # per-case ranks agree with R@k
        assert len(ranks) == 3 and ho["rows"][row]["r3_template"] == pytest.approx(sum(r < 3 for r in ranks) / 3)
        assert ho["rows"][row]["r1_template"] == pytest.approx(sum(r < 1 for r in ranks) / 3)
    # the template row is the main table's raw row: same motions, same captions
    assert ho["rows"]["template"]["r3_template"] == res.data["table"]["raw"]["r3_whole"]
    assert res.data["timing"]["phrasings_seconds"] > 0.0
    documented = set(re.findall(r"`([a-z0-9_]+)`", DOCS.read_text(encoding="utf-8")))
    nested = [
        ph,
        ph["probes"][-1],
        ph["probes"][0],
        ph["summary"],
        ph["summary"]["speed"]["4 sprint"],
        ph["summary"]["hand"][0],
        ph["captured"],
        ho,
        ho["pairs"][0],
        *ho["rows"].values(),
        ho["rows"],
    ]
    undocumented = {k for d in nested for k in d if k not in documented}
    assert not undocumented, undocumented
    table = format_phrasings_table(res.data)
    assert "| 4 sprint | 2 | 2 |" in table and "| Model (raw), held-out prompt |" in table
    assert "Probes the model warned are far from its training captions:" in table
    data = write_report(res, tmp_path / "out", filmstrips=0)
    md = (tmp_path / "out" / "report.md").read_text()
    assert "## Prompts in other words" in md and "A woman lifts her left arm up high." in md
    assert json.loads((tmp_path / "out" / "report.json").read_text())["phrasings"] == data["phrasings"]
    assert data["plots"]["phrasings"] == "plots/phrasings.png" and (tmp_path / "out" / "plots/phrasings.png").is_file()


@pytest.mark.parametrize(
    ("option", "value"), [("--phrasings", "-1"), ("--text-fraction", "0"), ("--text-fraction", "2")]
)
def test_cli_rejects_bad_phrasing_options(tiny_checkpoint, tiny_data, tmp_path, capsys, option, value):
    from kinema.cli import main

    argv = [
        "evaluate",
        "--model",
        str(tiny_checkpoint),
        "--data",
        str(tiny_data),
        "--out",
        str(tmp_path / "o"),
        option,
        value,
        "--no-progress",
    ]
    assert main(argv) == 2
    err = capsys.readouterr()
    lines = [ln for ln in (err.out + err.err).strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and option in lines[0], lines
    assert not (tmp_path / "o").exists()


def test_cli_checks_the_probe_joints_before_the_run(tiny_checkpoint, tiny_data, tmp_path, capsys, monkeypatch):
    from kinema.cli import main
    from kinema.evaluate import phrasings

    monkeypatch.setattr(phrasings, "PROBE_ROLES", ("pelvis", "tail"))  # a role the human skeleton lacks
    argv = ["evaluate", "--model", str(tiny_checkpoint), "--data", str(tiny_data), "--split", "train"]
    argv += ["--out", str(tmp_path / "o"), "--cases", "2", "--timeline-cases", "0", "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr()
    lines = [ln for ln in (err.out + err.err).strip().splitlines() if ln.strip() and not ln.startswith("suite:")]
    assert len(lines) == 1 and "--phrasings" in lines[0] and "tail" in lines[0], lines
    assert not (tmp_path / "o" / "report.json").exists()
