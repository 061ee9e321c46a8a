"""Post-processing: two-bone IK, correction blending, foot locking and exact constraint hitting."""

from __future__ import annotations

import math

import pytest
import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_mul
from kinema.motion.contacts import contact_joints, foot_contacts
from kinema.motion.core import Motion
from kinema.postprocess import PostTargets, postprocess
from kinema.postprocess.exact import constraint_residuals, hit_constraints
from kinema.postprocess.footlock import PAD_SECONDS, REACH_TOLERANCE, clean_contacts, foot_lock, foot_skate
from kinema.postprocess.ik import limb_chain, solve_ik, spread_corrections, two_bone_ik
from tests.test_skeleton import SCHEMES, humanoid


@pytest.fixture(scope="module")
def walk(walk_clip) -> Motion:
    """The Bandai walk at 20 fps (real, or the synthetic one of the same name: see conftest.py)."""
    from kinema.io.bvh import read_bvh

    return read_bvh(walk_clip, scale=0.01).prune(["joint_Root"]).resample(20)


def posed_humanoid(T=16, amount=0.4, seed=0) -> Motion:
    """The Bandai-named test humanoid (legs 0.4 m per segment) in random poses, pelvis 0.9 m up."""
    skel = humanoid(SCHEMES["bandai"])
    g = torch.Generator().manual_seed(seed)
    aa = amount * torch.randn(T, skel.num_joints, 3, generator=g, dtype=torch.float64)
    root = torch.tensor([0.0, 0.9, 0.0], dtype=torch.float64)
    root = root + 0.1 * torch.randn(T, 3, generator=g, dtype=torch.float64)
    return Motion(skel, 20, root, axis_angle_to_quat(aa))


def speeds(P: torch.Tensor, fps: float) -> torch.Tensor:
    return (P[1:] - P[:-1]).norm(dim=-1) * fps


# ----------------------------------------------------------------------------- IK


@pytest.mark.parametrize("limb", ["left_leg", "right_leg", "left_arm", "right_arm"])
def test_two_bone_ik_reaches_reachable_targets(limb):
    m = posed_humanoid()
    a, b, c = limb_chain(m.skeleton, limb)
    P = m.positions
    l1, l2 = m.skeleton.offsets[b].norm(), m.skeleton.offsets[c].norm()
    g = torch.Generator().manual_seed(1)
    direction = torch.nn.functional.normalize(torch.randn(m.num_frames, 3, generator=g, dtype=torch.float64), dim=-1)
    dist = abs(l1 - l2) + 0.05 + (l1 + l2 - abs(l1 - l2) - 0.06) * torch.rand(m.num_frames, 1, generator=g)
    target = P[:, a] + direction * dist
    out = solve_ik(m, limb, target)
    Q = out.positions
    assert (Q[:, c] - target).norm(dim=-1).max() < 1e-5
    # only the limb below a moves
    off_limb = [j for j in range(m.num_joints) if j == a or a not in m.skeleton.path_from_root(j)]
    assert torch.allclose(Q[:, off_limb], P[:, off_limb], atol=1e-9)
    # bone lengths are rigid
    assert torch.allclose((Q[:, b] - Q[:, a]).norm(dim=-1), l1.expand(m.num_frames).to(Q.dtype), atol=1e-9)


def test_two_bone_ik_clamps_unreachable_targets_along_the_chain_direction():
    m = posed_humanoid(seed=3)
    a, b, c = limb_chain(m.skeleton, "left_leg")
    P = m.positions
    reach = float(m.skeleton.offsets[b].norm() + m.skeleton.offsets[c].norm())
    g = torch.Generator().manual_seed(2)
    direction = torch.nn.functional.normalize(torch.randn(m.num_frames, 3, generator=g, dtype=torch.float64), dim=-1)
    out = solve_ik(m, "left_leg", P[:, a] + 3.0 * direction).positions
    assert (out[:, c] - (P[:, a] + reach * direction)).norm(dim=-1).max() < 1e-6
    # unequal bones (knee -> ankle -> toe) cannot fold closer than |l1 - l2| to the first joint
    a, b, c = m.skeleton.index("LowerLeg_L"), m.skeleton.index("Foot_L"), m.skeleton.index("Toes_L")
    arm = solve_ik(m, (a, b, c), P[:, a] + 1e-3 * direction).positions
    shortest = float((m.skeleton.offsets[b].norm() - m.skeleton.offsets[c].norm()).abs())
    assert ((arm[:, c] - P[:, a]).norm(dim=-1) - shortest).abs().max() < 1e-6


def test_straight_leg_bends_the_knee_forward_and_weights_blend():
    skel = humanoid(SCHEMES["bandai"])  # rest pose: legs straight down, facing +Z
    T = 5
    m = Motion(
        skel,
        20,
        torch.tensor([[0.0, 0.9, 0.0]] * T, dtype=torch.float64),
        axis_angle_to_quat(torch.zeros(T, skel.num_joints, 3, dtype=torch.float64)),
    )
    a, b, c = limb_chain(skel, "left_leg")
    P = m.positions
    target = P[:, c] + torch.tensor([0.0, 0.2, 0.0], dtype=torch.float64)
    weight = torch.tensor([0.0, 0.25, 0.5, 1.0, 1.0], dtype=torch.float64)
    out = solve_ik(m, "left_leg", target, weight=weight)
    Q = out.positions
    assert torch.equal(out.local_rotations[0], m.local_rotations[0])  # weight 0: bit-identical
    assert (Q[3:, c] - target[3:]).norm(dim=-1).max() < 1e-9
    assert (Q[3:, b, 2] > 0.1).all()  # the knee comes forward, not backward or sideways
    assert Q[1, b, 2] < Q[2, b, 2] < Q[3, b, 2]
    # the foot keeps its global rotation by default; an explicit end rotation is applied exactly
    assert torch.allclose(out.global_rotations[3:, c], m.global_rotations[3:, c], atol=1e-9)
    q = axis_angle_to_quat(torch.tensor([0.3, 0.2, -0.1], dtype=torch.float64)).expand(T, 4)
    rot = two_bone_ik(m.local_rotations, m.root_translation, skel, (a, b, c), target, end_rotation=q)
    G = Motion(skel, 20, m.root_translation, rot).global_rotations[:, c]
    assert torch.allclose(G.abs(), q.abs(), atol=1e-9)


def test_spread_corrections_is_exact_on_frames_and_fades_out():
    frames = torch.tensor([10, 14, 40])
    values = torch.tensor([[1.0], [2.0], [-1.0]], dtype=torch.float64)
    field, env = spread_corrections(frames, values, 60, radius=5.0)
    assert torch.equal(field[frames], values)
    assert torch.all(env[[10, 14, 40]] == 1)
    assert field[:5].abs().max() == 0 and field[46:].abs().max() == 0 and field[20:35].abs().max() == 0
    assert 1.0 < field[12, 0] < 2.0  # eases between close corrections
    assert field.diff(dim=0).abs().max() < 1.0  # no steps


# ----------------------------------------------------------------------------- foot locking


def test_clean_contacts_fills_gaps_and_drops_spikes():
    c = torch.zeros(30, 4)
    c[2:10, 0] = 0.9
    c[6, 0] = 0.2  # one-frame dropout inside a contact
    c[20, 1] = 0.8  # one-frame spike
    c[25:, 2] = 0.7  # contact running to the clip end
    out = clean_contacts(c, fps=20)
    assert out[2:10, 0].all() and not out[:2, 0].any() and not out[10:, 0].any()
    assert not out[:, 1].any()
    assert out[25:, 2].all()


def test_clean_contacts_pads_and_can_keep_single_frame_contacts():
    c = torch.zeros(12, 4)
    c[5, 0] = 0.9  # a one-frame contact, typical of a run's short stance at 20 fps
    c[0, 3] = 0.9
    out = clean_contacts(c, fps=20, min_seconds=0.0, pad_seconds=0.05)
    assert torch.nonzero(out[:, 0]).flatten().tolist() == [4, 5, 6]
    assert torch.nonzero(out[:, 3]).flatten().tolist() == [0, 1]
    assert not clean_contacts(c, fps=20, min_seconds=0.1)[5, 0]


def _sliding_walk(walk: Motion) -> tuple[Motion, torch.Tensor]:
    contacts = foot_contacts(walk.positions, walk.fps, walk.skeleton)
    t = torch.arange(walk.num_frames, dtype=torch.float64) / walk.fps
    root = walk.root_translation.clone()
    root[:, 0] += 0.04 * torch.sin(2 * math.pi * 1.3 * t)  # sway and surge: planted feet slide
    root[:, 2] += 0.03 * torch.sin(2 * math.pi * 0.9 * t + 1.0)
    return Motion(walk.skeleton, walk.fps, root, walk.local_rotations, contacts), contacts


def test_foot_lock_removes_added_foot_skate(walk):
    sliding, contacts = _sliding_walk(walk)
    out, report = foot_lock(sliding)
    planted = clean_contacts(contacts, walk.fps, min_seconds=0.0, pad_seconds=PAD_SECONDS)
    assert report["skate_before"] == pytest.approx(foot_skate(sliding, planted))
    assert report["skate_before"] > 15.0
    assert report["skate_after"] < 0.1 * report["skate_before"] and report["skate_after"] < 1.5
    assert report["max_ik_error_cm"] < 100 * REACH_TOLERANCE and report["root_shift_cm"] == 0.0
    P0, P1 = sliding.positions, out.positions
    legs = [j for s in ("left", "right") for j in limb_chain(walk.skeleton, f"{s}_leg")]
    legs += [walk.skeleton.roles["left_toe"], walk.skeleton.roles["right_toe"]]
    others = [j for j in range(walk.num_joints) if j not in legs]
    assert torch.allclose(P1[:, others], P0[:, others], atol=1e-9)
    # leg frames more than the blend (0.15 s = 3 frames) from any contact of that foot are untouched
    for k, side in ((0, "left"), (2, "right")):
        on = (planted[:, k] | planted[:, k + 1]).double()[None, None]
        near = torch.nn.functional.max_pool1d(on, 7, 1, 3)[0, 0] > 0  # planted is padded already
        chain = list(limb_chain(walk.skeleton, f"{side}_leg")) + [walk.skeleton.roles[f"{side}_toe"]]
        assert (~near).sum() > 10
        assert (P1[~near][:, chain] - P0[~near][:, chain]).norm(dim=-1).max() < 1e-6
    assert speeds(P1, walk.fps).max() <= 1.5 * speeds(P0, walk.fps).max()


def test_foot_lock_moves_the_pelvis_when_a_leg_cannot_reach(walk):
    """A body surging 12 cm back and forth over planted feet overstretches the legs; shifting the
    pelvis (smoothly, horizontally) lets the IK reach the locks that the legs alone cannot."""
    contacts = foot_contacts(walk.positions, walk.fps, walk.skeleton)
    t = torch.arange(walk.num_frames, dtype=torch.float64) / walk.fps
    root = walk.root_translation.clone()
    root[:, 2] += 0.12 * torch.sin(2 * math.pi * 1.1 * t)
    surging = Motion(walk.skeleton, walk.fps, root, walk.local_rotations, contacts)
    legs_only, r0 = foot_lock(surging, reach_passes=0)
    out, r3 = foot_lock(surging)
    assert r0["max_ik_error_cm"] > 2.0 and r0["root_shift_cm"] == 0.0
    assert 1.0 < r3["root_shift_cm"] < 15.0
    assert r3["max_ik_error_cm"] < 0.5 * r0["max_ik_error_cm"]
    assert r3["skate_after"] < r0["skate_after"]
    pelvis_step = (out.root_translation[1:] - out.root_translation[:-1]).norm(dim=-1).max()
    assert pelvis_step < 1.5 * (root[1:] - root[:-1]).norm(dim=-1).max()  # smooth: no pops
    assert torch.allclose(out.root_translation[:, 1], surging.root_translation[:, 1].to(out.dtype))


def test_foot_lock_plants_a_sliding_synthetic_stance():
    skel = humanoid(SCHEMES["bandai"])
    T, J = 30, skel.num_joints
    aa = torch.zeros(T, J, 3, dtype=torch.float64)
    for side in ("left", "right"):  # slightly bent knees so the legs have room to move
        hip, knee, ankle = limb_chain(skel, f"{side}_leg")
        aa[:, hip, 0], aa[:, knee, 0], aa[:, ankle, 0] = -0.3, 0.6, -0.3
    t = torch.arange(T, dtype=torch.float64) / 20
    root = torch.stack([0.03 * torch.sin(2 * math.pi * t), 0.86 + 0 * t, 0.02 * t], dim=-1)
    m = Motion(skel, 20, root, axis_angle_to_quat(aa), torch.ones(T, 4))
    out, report = foot_lock(m)
    feet = out.positions[:, contact_joints(skel)][..., [0, 2]]
    assert (feet - feet[:1]).norm(dim=-1).max() < 1e-6
    assert report["skate_after"] < 1e-4 < 1.0 < report["skate_before"]
    assert out.foot_contacts is not None and out.dtype == m.dtype


# ----------------------------------------------------------------------------- exact constraints


def _perturbed(walk: Motion, seed: int = 1) -> Motion:
    """The clip with smooth random joint-rotation noise (~5 deg) and a wandering root (~5 cm)."""
    T, J = walk.num_frames, walk.num_joints
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(T, dtype=torch.float64)
    amp = 0.08 * torch.randn(J, 3, generator=g, dtype=torch.float64)
    phase = 6 * torch.rand(J, 3, generator=g, dtype=torch.float64)
    noise = amp * torch.sin(2 * math.pi * t[:, None, None] / 40 + phase)
    root = walk.root_translation.clone()
    root[:, 0] += 0.05 * torch.sin(2 * math.pi * t / 60)
    root[:, 2] += 0.04 * torch.cos(2 * math.pi * t / 50)
    return Motion(walk.skeleton, walk.fps, root, quat_mul(walk.local_rotations, axis_angle_to_quat(noise)))


def _walk_targets(walk: Motion) -> PostTargets:
    roles = walk.skeleton.roles
    return PostTargets.from_motion(
        walk,
        full_body=[30],
        positions={roles["left_hand"]: [60], roles["right_ankle"]: [75], roles["left_toe"]: [100]},
        rotations={roles["left_hand"]: [60], roles["head"]: [110]},
        root_xz=[140, 150],
    )


def test_exact_pass_hits_constraints_on_a_perturbed_clip(walk):
    src, targets = _perturbed(walk), _walk_targets(walk)
    out, report = hit_constraints(src, targets)
    before, after = report["before"], report["after"]
    print("\nresiduals before -> after (max):", {k: f"{before[k]['max']:.3g} -> {after[k]['max']:.2g}" for k in before})
    assert (
        set(before)
        == set(after)
        == {"full_body_position_cm", "full_body_rotation_deg", "position_cm", "rotation_deg", "root_xz_cm"}
    )
    assert before["full_body_position_cm"]["max"] > 5 and before["root_xz_cm"]["max"] > 1
    for kind, stats in after.items():
        assert stats["max"] < 0.1, kind  # 1 mm, 0.1 deg
    # frames out of every constraint's reach are untouched (root waypoints reach ~1.5 s + blend)
    P0, P1 = src.positions, out.positions
    far = list(range(0, 22)) + list(range(38, 52)) + list(range(83, 92))
    assert (P1[far] - P0[far]).norm(dim=-1).max() < 1e-3
    assert report["max_change_outside_blend_cm"] < 0.1
    # blended edits: no jumps at the window edges
    assert speeds(P1, walk.fps).max() <= 1.5 * speeds(P0, walk.fps).max()
    acc = lambda P: (P[2:] - 2 * P[1:-1] + P[:-2]).norm(dim=-1).max()  # noqa: E731
    assert acc(P1) <= 1.5 * acc(P0)


def test_full_body_keyframes_from_positions_alone(walk):
    src = _perturbed(walk, seed=2)
    targets = PostTargets.from_motion(walk, positions={j: [40, 120] for j in range(walk.num_joints)})
    assert targets.full_body_frames(walk.num_joints).tolist() == [40, 120]
    out, report = hit_constraints(src, targets, iterations=0)
    assert report["before"]["full_body_position_cm"]["max"] > 5
    assert report["after"]["full_body_position_cm"]["max"] < 0.1
    assert speeds(out.positions, walk.fps).max() <= 1.5 * speeds(src.positions, walk.fps).max()


def test_exact_pass_without_optimisation_and_in_float32():
    src = posed_humanoid(T=40, amount=0.2, seed=5)
    g = torch.Generator().manual_seed(7)
    aa = 0.3 * torch.randn(40, src.num_joints, 3, generator=g, dtype=torch.float64)
    arm = list(limb_chain(src.skeleton, "right_arm"))
    aa[:, [j for j in range(src.num_joints) if j not in arm]] = 0  # hand targets within the arm's reach
    ref = Motion(src.skeleton, src.fps, src.root_translation, quat_mul(src.local_rotations, axis_angle_to_quat(aa)))
    hand = src.skeleton.roles["right_hand"]
    targets = PostTargets.from_motion(ref, full_body=[10], positions={hand: [25, 26]}, rotations={hand: [26]})
    out, report = hit_constraints(src.to(torch.float32), targets, iterations=0)
    assert out.dtype == torch.float32
    after = constraint_residuals(out, targets.validate(out))
    assert all(v["max"] < 0.1 for v in after.values()), after
    assert report["after"]["position_cm"]["max"] < 1e-3


def test_postprocess_chains_foot_lock_then_exact(walk):
    sliding, contacts = _sliding_walk(walk)
    targets = _walk_targets(walk)
    targets.contacts = (torch.arange(0, 20), contacts[:20])
    out, report = postprocess(sliding, targets)
    assert set(report) == {"smooth", "foot_lock", "exact", "plausibility", "warnings"}
    assert report["warnings"] == [] and "undone" not in report["exact"]
    assert report["foot_lock"]["skate_after"] < report["foot_lock"]["skate_before"]
    assert all(v["max"] < 0.1 for k, v in report["exact"]["after"].items() if k != "contact_skate_cm_s")
    assert out.foot_contacts is not None
    unchanged, rep = postprocess(sliding, None, foot_lock=False, smooth=0, smooth_rotations=0)
    assert unchanged is sliding and set(rep) == {"plausibility", "warnings"} and rep["warnings"] == []


def test_smoothing_removes_jitter_and_keeps_the_motion(walk):
    from kinema.postprocess.smooth import smooth_motion

    clean = walk.to(torch.float64)
    g = torch.Generator().manual_seed(0)
    aa = math.radians(2.0) * torch.randn(clean.local_rotations.shape[:2] + (3,), generator=g, dtype=torch.float64)
    root = clean.root_translation.clone()
    root[:, [0, 2]] += 0.02 * torch.randn(root.shape[0], 2, generator=g, dtype=torch.float64)  # ground-plane jitter
    noisy = Motion(clean.skeleton, clean.fps, root, quat_mul(clean.local_rotations, axis_angle_to_quat(aa)))
    # Sign flips on every other frame are the same rotations and must not change the result.
    flips = torch.ones(noisy.num_frames, 1, 1, dtype=torch.float64)
    flips[1::2] = -1
    flipped = Motion(noisy.skeleton, noisy.fps, noisy.root_translation, noisy.local_rotations * flips)
    out, report = smooth_motion(noisy, sigma_root=0.075, sigma_rot=0.075)
    out2, _ = smooth_motion(flipped, sigma_root=0.075, sigma_rot=0.075)
    assert torch.allclose(out.positions, out2.positions, atol=1e-9)
    assert report["accel_after_cm"] < 0.4 * report["accel_before_cm"], report
    err_noisy = (noisy.positions - clean.positions).norm(dim=-1).mean()
    err_out = (out.positions - clean.positions).norm(dim=-1).mean()
    assert err_out < 0.6 * err_noisy, (float(err_out), float(err_noisy))
    # The default (root x/z over one frame) barely moves a clean capture and keeps its vertical bounce.
    default, rep_clean = smooth_motion(clean)
    assert rep_clean["max_shift_cm"] < 1.0, rep_clean
    assert torch.equal(default.root_translation[:, 1], clean.root_translation[:, 1])
    assert torch.equal(default.local_rotations, clean.local_rotations)
    same, rep0 = smooth_motion(noisy, sigma_root=0.0)
    assert same is noisy and rep0["max_shift_cm"] == 0.0


def test_postprocess_smooths_shaking_limbs_and_keeps_a_clean_capture(walk):
    """Default post-processing filters rotations over 0.04 s: per-frame limb shake (the shipped model's
    main artefact) drops a lot, a clean capture moves by millimetres on average."""
    from kinema.evaluate.metrics import jerk

    clean = walk.to(torch.float64)
    g = torch.Generator().manual_seed(1)
    aa = math.radians(3.0) * torch.randn(clean.local_rotations.shape[:2] + (3,), generator=g, dtype=torch.float64)
    shaking = Motion(
        clean.skeleton, clean.fps, clean.root_translation, quat_mul(clean.local_rotations, axis_angle_to_quat(aa))
    )
    kw = dict(foot_lock=False)
    out, rep = postprocess(shaking, **kw)
    assert rep["smooth"]["sigma_rot_s"] == 0.04
    assert jerk(out) < 0.5 * jerk(shaking)
    kept, _ = postprocess(clean, **kw)
    assert (kept.positions - clean.positions).norm(dim=-1).mean() < 0.005
    off, _ = postprocess(shaking, smooth_rotations=0.0, **kw)
    assert torch.allclose(off.local_rotations, shaking.local_rotations)


def test_targets_are_validated():
    m = posed_humanoid(T=10)
    with pytest.raises(KinemaError, match="frames must lie"):
        PostTargets(joint_positions={3: (torch.tensor([12]), torch.zeros(1, 3))}).validate(m)
    with pytest.raises(KinemaError, match="joint 99"):
        PostTargets(joint_rotations={99: (torch.tensor([1]), torch.zeros(1, 4))}).validate(m)
    with pytest.raises(KinemaError, match="2 frames but 1"):
        PostTargets(root_xz=(torch.tensor([1, 2]), torch.zeros(1, 2))).validate(m)
    assert PostTargets().is_empty()
