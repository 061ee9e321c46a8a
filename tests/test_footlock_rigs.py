"""Foot locking and IK on rigs other than the human: six legs, four legs, none (a fish)."""

from __future__ import annotations

import torch
from rig_fixtures import fish, hexapod, human, quadruped, walking

from kinema.motion.contacts import foot_contacts
from kinema.postprocess import postprocess
from kinema.postprocess.footlock import foot_lock, leg_locks
from kinema.postprocess.ik import solve_ik
from kinema.rig import Rig


def _planted(motion, rig, frames=slice(5, 20)) -> torch.Tensor:
    contacts = torch.zeros(motion.num_frames, rig.num_contacts)
    contacts[frames] = 1.0
    return contacts


def test_leg_locks_follow_the_rig() -> None:
    human_legs = leg_locks(Rig.from_skeleton(human()))
    skel = human()
    assert [tuple(skel.names[j] for j in leg.chain) for leg in human_legs] == [
        ("UpperLeg_L", "LowerLeg_L", "Foot_L"),
        ("UpperLeg_R", "LowerLeg_R", "Foot_R"),
    ]
    assert [(leg.heel, leg.toe) for leg in human_legs] == [(0, 1), (2, 3)]
    insect = leg_locks(Rig.from_skeleton(hexapod()))
    assert len(insect) == 6 and all(leg.toe is None for leg in insect)
    assert sorted(leg.heel for leg in insect) == list(range(6))
    assert len(leg_locks(Rig.from_skeleton(quadruped()))) == 4
    assert leg_locks(Rig.from_skeleton(fish())) == []


def test_six_legged_foot_lock_pins_planted_feet() -> None:
    skel = hexapod()
    rig = Rig.from_skeleton(skel)
    motion = walking(skel, speed=0.1)
    out, report = foot_lock(motion, _planted(motion, rig), rig=rig)
    assert report["segments"] == 6
    assert report["skate_before"] > 8.0 and report["skate_after"] < 0.2 * report["skate_before"], report
    feet = out.positions[5:20, list(rig.contacts)]
    drift = (feet[..., [0, 2]] - feet[:1, :, [0, 2]]).norm(dim=-1).max()
    assert drift < 0.01, drift  # within a centimetre over the planted frames
    free = (out.positions[:2] - motion.positions[:2]).abs().max()
    assert free < 1e-6  # frames far from contacts are untouched


def test_quadruped_and_estimated_contacts() -> None:
    skel = quadruped()
    rig = Rig.from_skeleton(skel)
    motion = walking(skel, speed=0.1)
    est = foot_contacts(motion.positions, motion.fps, skel, joints=rig.contacts)
    assert est.shape == (motion.num_frames, 8)
    out, report = foot_lock(motion, _planted(motion, rig), rig=rig)
    assert report["skate_after"] < 0.3 * report["skate_before"], report


def test_fish_has_nothing_to_lock_and_postprocess_runs() -> None:
    skel = fish()
    motion = walking(skel, speed=0.5)
    out, report = foot_lock(motion)
    assert out is motion and report["segments"] == 0
    done, report = postprocess(motion)
    assert done.num_frames == motion.num_frames and torch.isfinite(done.positions).all()
    assert report["foot_lock"]["segments"] == 0


def test_postprocess_on_a_hexapod_with_six_contact_channels() -> None:
    skel = hexapod()
    rig = Rig.from_skeleton(skel)
    motion = walking(skel, speed=0.1)
    motion.foot_contacts = _planted(motion, rig).double()
    done, report = postprocess(motion, rig=rig)
    assert done.foot_contacts.shape == (motion.num_frames, 6)
    assert report["foot_lock"]["segments"] == 6


def test_ik_reaches_with_an_insect_leg() -> None:
    skel = hexapod()
    rig = Rig.from_skeleton(skel)
    leg = leg_locks(rig)[0]
    motion = walking(skel, frames=5)
    P = motion.positions
    target = P[:, leg.chain[2]] + torch.tensor([0.02, 0.0, 0.01], dtype=torch.float64)
    out = solve_ik(motion, leg.chain, target)
    assert (out.positions[:, leg.chain[2]] - target).norm(dim=-1).max() < 1e-4
