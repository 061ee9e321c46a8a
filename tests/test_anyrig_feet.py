"""Any-rig foot clean-up: grounding by contact joints, locking of feet moved by translation (synthetic rigs)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

import kinema
from kinema.anyrig.feet import REACH, descendants, lock_translated_feet, translated_feet
from kinema.anyrig.ground import ground_motion, ground_offsets, leg_ends, settle_offsets, steady_height
from kinema.anyrig.post import dejitter, reach_by_translation
from kinema.constraints.character import JointTarget
from kinema.evaluate.metrics import position_jerk
from kinema.io.gltf import read_gltf
from kinema.motion.core import Motion
from kinema.postprocess import postprocess
from kinema.postprocess.targets import PostTargets
from kinema.representation.joint import JointRepresentation
from kinema.rig import Rig
from kinema.skeleton import Skeleton

FPS = 20.0
SHARED_QUATERNIUS = (
    Path(os.environ.get("KINEMA_DATASETS") or Path(__file__).resolve().parents[2] / "shared/datasets") / "quaternius"
)


def _biped(frames: int, foot_x: torch.Tensor, foot_y: torch.Tensor, lift: float = 0.0) -> Motion:
    """A game rig 1 unit tall: a floor-level armature, a body and two IK feet (with toes) moved by
    translation. Foot 1 follows ``foot_x``/``foot_y`` (x, height of its toe); the whole motion is raised
    by ``lift`` (negative: sunk into the floor)."""
    skel = Skeleton(
        ["Armature", "Body", "Head", "IK.L", "Toe.L", "IK.R", "Toe.R"],
        [-1, 0, 1, 0, 3, 0, 5],
        [[0, 0, 0], [0, 0.6, 0], [0, 0.4, 0], [0.1, 0.05, 0], [0, -0.03, 0.1], [-0.1, 0.05, 0], [0, -0.03, 0.1]],
        name="biped",
    )
    lt = skel.offsets[None].repeat(frames, 1, 1).clone()
    lt[:, 3, 0] += foot_x
    lt[:, 3, 1] += foot_y
    root = torch.zeros(frames, 3, dtype=torch.float64)
    root[:, 1] = lift
    rots = torch.zeros(frames, 7, 4, dtype=torch.float64)
    rots[..., 0] = 1.0
    return Motion(skel, FPS, root, rots, None, lt)


def _rig(m: Motion) -> Rig:
    d = Rig.from_skeleton(m.skeleton).to_dict()
    d["contacts"] = [4, 6]  # the toes
    return Rig.from_dict({k: v for k, v in d.items() if k != "skeleton"}, skeleton=m.skeleton)


def _floor_speed(P: torch.Tensor, j: int, below: float) -> torch.Tensor:
    """Horizontal speeds (units/s) of joint ``j`` between consecutive frames both lower than ``below``."""
    low = P[:, j, 1] < below
    both = low[1:] & low[:-1]
    speed = (P[1:, j, [0, 2]] - P[:-1, j, [0, 2]]).norm(dim=-1) * FPS
    return speed[both]


def test_a_foot_sliding_fast_along_the_floor_is_locked_and_steps_after_the_body() -> None:
    T = 40
    slide = torch.arange(T, dtype=torch.float64) * 1.0 / FPS  # 1 rig size per second, on the floor
    m = _biped(T, slide, torch.zeros(T))
    rig = _rig(m)
    feet = translated_feet(rig, rig.root)
    assert [(f.joint, f.soles) for f in feet] == [(3, (4,)), (5, (6,))]
    before = _floor_speed(m.positions, 4, 0.03)
    assert before.numel() > 30 and float(before.mean()) > 0.99  # skates at full speed
    out, rep = lock_translated_feet(m, feet, 1.0)
    P = out.positions
    on_floor = _floor_speed(P, 4, 0.03)
    assert float(on_floor.max()) < 1e-9  # wherever the toe touches the floor, it stands still
    assert rep["translated_feet_steps"] >= 4  # it keeps up with the body by stepping ...
    assert float((P[:, 4, 0] - m.positions[:, 4, 0]).abs().max()) < REACH + 0.3  # ... never far behind
    assert float(P[:, 4, 1].max()) > 0.04  # ... lifted off the floor to step
    assert float(P[:, 4, 1].min()) > 0.02 - 1e-9  # and never below its stand (rest height 0.02)


def test_a_sunk_motion_is_grounded_by_its_contact_joints_and_keeps_a_jump_arc() -> None:
    T = 30
    t = torch.arange(T, dtype=torch.float64)
    jump = torch.where((t >= 10) & (t < 20), 0.3 + 0.2 * torch.sin(torch.pi * (t - 9) / 11), torch.zeros(T))
    m = _biped(T, torch.zeros(T), torch.zeros(T), lift=-0.4)
    m = Motion(
        m.skeleton,
        FPS,
        m.root_translation + torch.stack([0 * t, jump, 0 * t], 1),
        m.local_rotations,
        None,
        m.local_translations,
    )
    down = torch.ones(T, 2)
    down[10:20] = 0.0  # the model says: airborne during the jump (and it is higher than HOVER)
    m = Motion(m.skeleton, FPS, m.root_translation, m.local_rotations, down, m.local_translations)
    out, off = ground_motion(m, m, [4, 6], [0.02, 0.02])
    P = out.positions
    assert abs(off - 0.4) < 1e-6
    assert torch.allclose(P[:, 4, 1], 0.02 + jump, atol=1e-6)  # on the floor where down, the arc kept
    assert torch.allclose(P[:, 2] - P[:, 0], m.positions[:, 2] - m.positions[:, 0])  # a rigid shift


def test_grounding_offsets_lift_out_of_the_floor_without_any_contact() -> None:
    clear = torch.tensor([0.2, -0.1, -0.1, 0.3, 0.3])
    off = ground_offsets(clear, torch.zeros(5, dtype=torch.bool), FPS)
    assert float(off.min()) >= 0 and torch.all(off[1:3] >= 0.1)  # lifted out of the dip, never lowered
    assert torch.equal(ground_offsets(torch.full((5,), 0.2), torch.zeros(5, dtype=torch.bool), FPS), torch.zeros(5))


def test_foot_jitter_is_filtered_but_joint_targets_on_the_foot_stay_exact() -> None:
    T = 40
    g = torch.Generator().manual_seed(0)
    swing = 0.2 * torch.sin(torch.arange(T, dtype=torch.float64) / 4)
    jitter = 0.01 * torch.randn(T, generator=g, dtype=torch.float64)
    m = _biped(T, swing + jitter, torch.full((T,), 0.2) + jitter)  # in the air: never planted
    rig = _rig(m)
    feet = translated_feet(rig, rig.root)
    out, rep = lock_translated_feet(m, feet, 1.0, hold={4: [15]})
    assert rep["translated_feet_segments"] == 1  # the right foot, standing still
    jerk_before, jerk_after = (position_jerk(x.positions[:, [3, 4]], FPS) for x in (m, out))
    assert jerk_after < 0.5 * jerk_before
    assert torch.allclose(out.positions[15], m.positions[15], atol=1e-12)  # the constrained frame is kept
    assert float((out.positions[:, 3] - m.positions[:, 3]).norm(dim=-1).max()) < 0.03  # a filter, not a move
    assert torch.allclose(out.positions[:, [0, 1, 2, 5, 6]], m.positions[:, [0, 1, 2, 5, 6]])  # the rest stays


def test_a_foot_hovering_steadily_above_the_floor_is_put_down_and_locked() -> None:
    T = 20
    slide = torch.arange(T, dtype=torch.float64) * 0.1 / FPS
    m = _biped(T, slide, torch.full((T,), 0.08))  # hovers 0.08 above its stand at a steady height, sliding
    rig = _rig(m)
    out, rep = lock_translated_feet(m, translated_feet(rig, rig.root), 1.0)
    assert rep["translated_feet_segments"] == 2
    assert torch.allclose(out.positions[:, 4, 1], torch.full((T,), 0.02, dtype=torch.float64))  # put down
    assert float((out.positions[1:, 4, [0, 2]] - out.positions[:-1, 4, [0, 2]]).abs().max()) < 1e-9


def test_model_contact_channel_locks_a_bobbing_foot_where_it_says_so() -> None:
    T = 20
    t = torch.arange(T, dtype=torch.float64)
    bob = 0.09 + 0.05 * torch.cos(2 * torch.pi * t / 10)  # 0.04 .. 0.14 above its stand
    m = _biped(T, torch.zeros(T), bob)
    rig = _rig(m)
    feet = translated_feet(rig, rig.root)
    free, _ = lock_translated_feet(m, feet, 1.0)
    down = free.positions[:, 4, 1] < 0.02 + 1e-9
    assert 0 < int(down.sum()) < T  # only near the bottom of each bob
    said = torch.zeros(T, 2)
    said[:, 0] = 0.9
    out, rep = lock_translated_feet(m, feet, 1.0, contacts=said)
    assert torch.allclose(out.positions[:, 4, 1], torch.full((T,), 0.02, dtype=torch.float64))  # down throughout


def test_a_planted_foot_holds_its_rotation_so_its_toe_stands_still() -> None:
    T = 20
    m = _biped(T, torch.zeros(T), torch.zeros(T))
    angle = 0.3 * torch.sin(torch.arange(T, dtype=torch.float64))  # the IK bone shakes about the vertical
    rots = m.local_rotations.clone()
    rots[:, 3, 0], rots[:, 3, 2] = torch.cos(angle / 2), torch.sin(angle / 2)
    m = Motion(m.skeleton, FPS, m.root_translation, rots, None, m.local_translations)
    assert float(_floor_speed(m.positions, 4, 0.03).mean()) > 0.3  # the toe swings along the floor
    rig = _rig(m)
    out, _ = lock_translated_feet(m, translated_feet(rig, rig.root), 1.0)
    assert float(_floor_speed(out.positions, 4, 0.03).max()) < 1e-9
    assert torch.allclose(out.local_rotations[:, [0, 1, 2, 4, 5, 6]], m.local_rotations[:, [0, 1, 2, 4, 5, 6]])


def test_steady_height_removes_root_height_shaking_and_keeps_slow_motion() -> None:
    T = 40
    g = torch.Generator().manual_seed(1)
    t = torch.arange(T, dtype=torch.float64) / FPS
    slow = 0.1 * torch.sin(2 * torch.pi * 0.5 * t)  # a slow crouch
    m = _biped(T, torch.zeros(T), torch.zeros(T))
    root = m.root_translation.clone()
    root[:, 1] = 0.5 + slow + 0.02 * torch.randn(T, generator=g, dtype=torch.float64)
    m = Motion(m.skeleton, FPS, root, m.local_rotations, None, m.local_translations)
    out, change = steady_height(m)
    assert 0 < change < 0.05
    assert position_jerk(out.positions, FPS) < 0.5 * position_jerk(m.positions, FPS)
    assert float((out.root_translation[:, 1] - 0.5 - slow).abs().mean()) < 0.02  # the crouch stays
    assert torch.equal(out.root_translation[:, [0, 2]], m.root_translation[:, [0, 2]])
    flat = Motion(
        m.skeleton, FPS, torch.zeros(T, 3, dtype=torch.float64), m.local_rotations, None, m.local_translations
    )
    assert torch.equal(steady_height(flat)[0].root_translation, flat.root_translation)


def test_dejitter_keeps_smoothing_a_shaking_pelvis_that_the_shared_guard_would_undo() -> None:
    T = 40
    g = torch.Generator().manual_seed(2)
    m = _biped(T, torch.zeros(T), torch.zeros(T))
    root = m.root_translation.clone()
    root[:, [0, 2]] += 0.3 * torch.randn(T, 2, generator=g, dtype=torch.float64)  # shakes at ~6 units/s
    m = Motion(m.skeleton, FPS, root, m.local_rotations, None, m.local_translations)
    _, shared = postprocess(m, foot_lock=False, exact=False)
    assert "undone" in shared["smooth"]  # the shared guard calls this dragging the pelvis
    out, report, warnings = dejitter(m)
    assert not warnings and "undone" not in report
    assert position_jerk(out.positions, FPS) < 0.5 * position_jerk(m.positions, FPS)


def test_a_planted_foot_stands_still_when_the_armature_turns_with_the_body() -> None:
    T = 20
    m = _biped(T, torch.zeros(T), torch.zeros(T))
    angle = 0.2 * torch.sin(torch.arange(T, dtype=torch.float64) / 2)  # joint 0 turns with the body
    rots = m.local_rotations.clone()
    rots[:, 0, 0], rots[:, 0, 2] = torch.cos(angle / 2), torch.sin(angle / 2)
    m = Motion(m.skeleton, FPS, m.root_translation, rots, None, m.local_translations)
    assert float(_floor_speed(m.positions, 4, 0.03).mean()) > 0.1
    rig = _rig(m)
    out, _ = lock_translated_feet(m, translated_feet(rig, rig.root), 1.0)
    assert float(_floor_speed(out.positions, 4, 0.03).max()) < 1e-9


def test_settle_offsets_measure_how_far_the_body_floats_above_its_feet() -> None:
    skel = Skeleton(
        ["Armature", "Body", "Knee.L", "Shin.L", "IK.L", "Head"],
        [-1, 0, 1, 2, 0, 1],
        [[0, 0, 0], [0, 0.6, 0], [0.1, -0.2, 0], [0, -0.3, 0], [0.1, 0.05, 0], [0, 0.4, 0]],
        name="legged",
    )
    legs = leg_ends(skel, [4], descendants(skel, [4]), 1.0)  # only IK.L moves by translation
    assert [(h, e) for h, e, _ in legs] == [(4, 3)]  # the shin's end is the foot's leg
    assert abs(legs[0][2] - 0.05) < 1e-9  # at rest the shin ends 0.05 above the IK foot
    T = 30
    lift = torch.where(torch.arange(T) < 15, 0.2, 0.0).double()  # the body floats 0.2 up, then stands
    lt = skel.offsets[None].repeat(T, 1, 1).clone()
    lt[:, 1, 1] += lift
    rots = torch.zeros(T, 6, 4, dtype=torch.float64)
    rots[..., 0] = 1.0
    m = Motion(skel, FPS, torch.zeros(T, 3, dtype=torch.float64), rots, None, lt)
    g = settle_offsets(m.positions, legs, FPS, 1.0)
    assert abs(float(g[0]) - 0.2) < 1e-3 and abs(float(g[-1])) < 1e-3  # held at the ends
    assert float(g[13]) > float(g[16])  # smoothed across the change, not a jump
    far = leg_ends(skel, [4], [4], 0.1)  # a rig 0.1 across: the shin is beyond LEG_REACH
    assert far == []


def test_joint_targets_met_by_translating_the_carrying_bone() -> None:
    """A target the rotation-only exact pass left unmet (the head of a body moved by translation) is met
    by translating the nearest bone that carries a translation, blended over 0.3 s: exact on the target
    frame, frames beyond the blend untouched; a target on a joint right below joint 0 moves joint 0; a
    miss above the limit, or with no movable ancestor, is left alone (the unmet warning reports it)."""
    m = _biped(40, torch.zeros(40), torch.zeros(40))
    frames = torch.tensor([20])
    goal = m.positions[20, 2] + torch.tensor([0.05, -0.02, 0.03], dtype=torch.float64)
    targets = PostTargets(joint_positions={2: (frames, goal[None])})
    new, moved = reach_by_translation(m, targets, {0, 1, 3, 5})
    P, P0 = new.positions, m.positions
    assert torch.allclose(P[20, 2], goal, atol=1e-9) and set(moved) == {"Head"}
    assert torch.equal(new.root_translation, m.root_translation)  # the body bone moved, not joint 0
    assert torch.allclose(P[:, 3:], P0[:, 3:])  # the feet hang from the armature: untouched
    far = [f for f in range(40) if abs(f - 20) > 6]
    assert torch.allclose(P[far], P0[far])
    shift = (P[:, 2] - P0[:, 2]).norm(dim=-1)
    assert float(shift[17:24].min()) > 0 and float((shift[1:] - shift[:-1]).abs().max()) < 0.02  # eased in
    whole, _ = reach_by_translation(m, targets, {0})
    assert torch.allclose(whole.positions[20, 2], goal, atol=1e-9)
    assert torch.allclose(whole.positions[20] - P0[20], (goal - P0[20, 2]).expand(7, 3), atol=1e-9)  # rigid
    too_far = PostTargets(joint_positions={2: (frames, (goal + 1.0)[None])})
    assert reach_by_translation(m, too_far, {0, 1}) == (m, {})
    assert reach_by_translation(m, targets, set()) == (m, {})


def test_snake_head_target_met_on_the_shipped_model() -> None:
    """The real snake hangs its body from a floor-level armature and moves it by translation, which the
    rotation-only exact pass cannot change: its head target was left 10-16 cm off (rig of 1 m) before
    `reach_by_translation`. Target: the head where the snake's own attack clip has it mid-clip."""
    path = SHARED_QUATERNIUS / "easy_enemies_pack" / "Snake.glb"
    if not path.is_file():
        pytest.skip("needs the shared Quaternius data")
    model = kinema.load_model("creatures")
    ref = read_gltf(path, fps=model.fps).motions["SnakeArmature|Snake_Attack"]
    rig = model.resolve_rig(path)
    f = ref.num_frames // 2
    pos = JointRepresentation(rig, model.fps).from_motion(ref.to(torch.float64))[f, rig.skeleton.index("Head"), 0:3]
    target = JointTarget(joint="Head", frame=f, position=tuple(float(v) for v in pos))
    res = model.generate("A snake attacks.", rig=path, seconds=2, steps=10, seed=0, constraints=[target])
    assert max(res.report.residuals_cm) < 0.5, res.report.residuals_cm
    assert not [w for w in res.report.warnings if "not met" in w]
    assert "Head" in res.report.reached_by_translation
