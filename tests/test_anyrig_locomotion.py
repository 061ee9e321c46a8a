"""Issue 34's locomotion measures (kinema.evaluate.anyrig.locomotion) on a real Quaternius rig and on the
shipped model's output there: forward share, turning, drift and speed of the root's ground path, the
foot-to-leg gap against the rig's own clips, and the `kinema evaluate-anyrig` columns built from them."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
import torch

import kinema
from kinema.anyrig.feet import rest_extent
from kinema.evaluate.anyrig.locomotion import foot_gap_ratio, ground_measures, probe_prompts, rig_ties
from kinema.evaluate.anyrig.suite import LOCOMOTION_HEADER, evaluate_rig, format_locomotion_row
from kinema.geometry.rotations import quat_mul, quat_rotate
from kinema.io.gltf import read_gltf
from kinema.motion.core import Motion
from kinema.representation.joint import JointRepresentation, yaw_quat
from kinema.rig import Rig

RAT = (
    Path(os.environ.get("KINEMA_DATASETS") or Path(__file__).resolve().parents[2] / "shared/datasets")
    / "quaternius/easy_enemies_pack/Rat.glb"
)


@pytest.fixture(scope="module")
def rat() -> dict[str, Motion]:
    """The rat's clips in rig units (the rest pose 1 across), by action."""
    if not RAT.is_file():
        pytest.skip("needs the shared Quaternius data")
    clips = read_gltf(RAT, fps=20).motions
    k = 1.0 / rest_extent(next(iter(clips.values())).skeleton)
    out = {}
    for name, m in clips.items():
        lt = None if m.local_translations is None else m.local_translations * k
        out[name.split("_")[-1].lower()] = Motion(
            m.skeleton.scaled(k), m.fps, m.root_translation * k, m.local_rotations, m.foot_contacts, lt
        )
    return out


def _moved(m: Motion, speed: float, turn: float, back: bool = False) -> Motion:
    """``m`` carried over the ground at ``speed`` (rig units/s) along its facing (backwards with
    ``back``) while turning at ``turn`` rad/s about its root."""
    rep = JointRepresentation(Rig.from_skeleton(m.skeleton), m.fps)
    T, dt = m.num_frames, 1.0 / m.fps
    psi0 = rep.heading(m.to(torch.float64).global_rotations)
    yaw = torch.arange(T, dtype=torch.float64) * turn * dt
    face = psi0 + yaw
    step = torch.stack([torch.sin(face), torch.zeros(T, dtype=torch.float64), torch.cos(face)], -1) * speed * dt
    path = torch.cumsum(step, 0) * (-1.0 if back else 1.0)
    q = yaw_quat(yaw)
    pivot = m.to(torch.float64).positions[:, rep.rig.root]
    rot = m.local_rotations.to(torch.float64).clone()
    rot[:, 0] = quat_mul(q, rot[:, 0])
    trans = pivot + quat_rotate(q, m.root_translation.to(torch.float64) - pivot) + path
    return Motion(m.skeleton, m.fps, trans, rot, m.foot_contacts, m.local_translations)


def test_ground_path_measures_on_the_rats_own_walk(rat) -> None:
    """The rat's walk clip (in place, tiled to 4 s) carried forward, backwards or turned on the spot: the
    measures say straight ahead / tail first / turning in place, in body sizes."""
    walk = rat["walk"]
    reps = math.ceil(80 / walk.num_frames)
    lt = walk.local_translations.repeat(reps, 1, 1)[:80]
    long = Motion(walk.skeleton, walk.fps, walk.root_translation.repeat(reps, 1)[:80],
                  walk.local_rotations.repeat(reps, 1, 1)[:80], None, lt)  # fmt: skip
    rep = JointRepresentation(Rig.from_skeleton(long.skeleton), long.fps)
    still = ground_measures(long, rep)
    assert still["drift"] < 0.1 and still["net_turn_deg"] < 5  # the clip walks on the spot
    ahead = ground_measures(_moved(long, 0.5, 0.0), rep)
    assert ahead["forward_share"] > 0.95 and ahead["speed"] == pytest.approx(0.5, rel=0.15)
    assert ahead["travel"] == pytest.approx(0.5 * 79 / 20, rel=0.1) and ahead["net_turn_deg"] < 5
    backwards = ground_measures(_moved(long, 0.5, 0.0, back=True), rep)
    assert backwards["forward_share"] < -0.95
    spin = ground_measures(_moved(long, 0.0, math.radians(45)), rep)  # 45 deg/s for 3.95 s
    assert spin["net_turn_deg"] == pytest.approx(45 * 79 / 20, abs=5) and spin["travel"] < 0.1
    assert spin["total_turn_deg"] >= spin["net_turn_deg"]


def test_ties_and_probe_prompts_from_the_rats_clips(rat) -> None:
    """Every IK foot of the rat is tied to its lower leg; its own clips stay within their largest gap
    (ratio <= 1 by definition), one with a foot pulled off its leg does not."""
    rep = JointRepresentation(Rig.from_skeleton(rat["walk"].skeleton), 20.0)
    ties = rig_ties(rep, list(rat.values()))
    names = {rep.rig.skeleton.names[t.joint]: rep.rig.skeleton.names[t.anchor] for t in ties.ties}
    assert names == {"FrontFoot.L": "FrontLowLeg.L", "FrontFoot.R": "FrontLowLeg.R", "BackFoot.L": "BackLowLeg.L",
                     "BackFoot.R": "BackLowLeg.R"}  # fmt: skip
    assert max(foot_gap_ratio(m, ties) for m in rat.values()) <= 1.0 + 1e-6
    foot = rep.rig.skeleton.index("BackFoot.L")
    lt = rat["walk"].local_translations.clone()
    lt[:, foot] += 0.3  # the foot bone moved 0.5 body sizes, the leg where it was
    torn = Motion(rat["walk"].skeleton, 20.0, rat["walk"].root_translation, rat["walk"].local_rotations, None, lt)
    assert foot_gap_ratio(torn, ties) > 1.5
    prompts = probe_prompts(["walk", "idle", "run"], ["A rat walks.", "A rat stands idle.", "A rat runs."])
    assert prompts == {"idle": "A rat stands idle.", "walk": "A rat walks forward.", "run": "A rat runs."}
    assert probe_prompts(["gallop", "run"], ["A fox gallops.", "A fox runs."])["run"] == "A fox gallops."


def test_evaluate_rig_reports_locomotion_of_the_shipped_models_output(rat) -> None:
    """The shipped model on the rat (2 DDIM steps, 1-s probes): the row has the gap, forward share,
    turning, idle drift and speeds per action next to the rat's own clips, and the table row prints."""
    model = kinema.load_model("creatures")
    own = [(rat[a], a, f"A rat {v}.") for a, v in (("walk", "walks"), ("idle", "stands idle"), ("run", "runs"))]
    row = evaluate_rig(model, "rat", [rat["walk"]], ["A rat walks."], steps=2, own=own, probe_seconds=1.0)
    assert row["walk_prompt"] == "A rat walks forward." and row["ties"] == 4
    assert row["gap_ratio"] is not None and row["gap_ratio"] > 0
    assert -1.0 <= row["walk_forward_share"] <= 1.0 and row["walk_total_turn_deg"] >= row["walk_net_turn_deg"]
    assert row["idle_drift"] >= 0 and row["idle_speed_ref"] < 0.05  # the rat's own idle stands still
    assert row["run_walk_ratio"] == pytest.approx(row["run_speed"] / row["walk_speed"])
    row["split"] = "test"
    line = format_locomotion_row(row)
    assert line.count("|") == LOCOMOTION_HEADER.splitlines()[0].count("|") and line.startswith("| rat | test | 4 |")
