"""Putting a generated any-rig motion on the floor: one vertical offset per frame.

The any-rig model predicts the root's height and the joints' positions relative to the root
separately, and on small CPU-trained weights the two disagree: on the shipped ``creatures`` model a
husky standing idle had its feet 0.3-0.5 rig sizes *below* the floor (root at 0.3 instead of 0.58),
so every foot counted as planted and slid with the body. The rig's rest pose says where each contact
joint stands (its height above the lowest rest joint); ``ground_offsets`` lifts or lowers the whole
motion so that, on frames where a foot is down, the lowest contact joint stands exactly there, and
interpolates the offset across airborne frames (a jump keeps its arc). A foot is down where the
lowest contact joint is within ``HOVER`` of the lowest it comes within ``BASELINE_SECONDS`` (the
floor as the motion itself has it, sunk or floating; a jump rises above it), or where the model's
contact channel says so and it is within twice that. The channel alone is not enough: the two-legged
gun robot flagged 3 % of an attack's frames and hovered above the floor on the rest, where its own
clips stand on it 94 % of the time. The offsets are low-passed (``SIGMA_SECONDS``) so the body does
not shake with the feet, and never leave a contact joint below its stand. Heights in the motion's
units; shapes ``(T, C)``; y up.
"""

from __future__ import annotations

import torch

from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time
from kinema.rig.find import rest_positions
from kinema.skeleton import Skeleton

SIGMA_SECONDS = 0.1
HEIGHT_SIGMA_SECONDS = 0.05  # the root height's own de-jittering (``steady_height``)
HOVER = 0.15  # x rig size: a lowest contact joint this close to its lowest level nearby is meant to be down
BASELINE_SECONDS = 1.0  # "nearby": a window this long (longer than a jump)


def ground_offsets(clearance: torch.Tensor, down: torch.Tensor, fps: float) -> torch.Tensor:
    """``(T,)`` vertical offsets from ``clearance (T,)`` (the lowest contact joint's height above its
    stand) and ``down (T,)`` (some foot is on the floor): ``-clearance`` on ``down`` frames,
    linear in between (held before the first and after the last), smoothed, and at least ``-clearance``
    everywhere. No ``down`` frame at all: only lifted out of the floor."""
    T = clearance.shape[0]
    want = torch.zeros(T, dtype=clearance.dtype)
    idx = torch.nonzero(down).flatten()
    if idx.numel():
        t = torch.arange(T, dtype=clearance.dtype)
        x, y = idx.to(clearance.dtype), -clearance[idx]
        k = torch.searchsorted(x, t).clamp(1, max(idx.numel() - 1, 1))
        if idx.numel() == 1:
            want[:] = y[0]
        else:
            x0, x1, y0, y1 = x[k - 1], x[k], y[k - 1], y[k]
            want = y0 + (y1 - y0) * ((t - x0) / (x1 - x0)).clamp(0.0, 1.0)
    want = torch.maximum(want, -clearance)
    r = int(3 * SIGMA_SECONDS * fps) + 1  # ends held (not point-reflected): an offset is not a path
    padded = torch.cat([want[:1].expand(r), want, want[-1:].expand(r)])
    smooth = smooth_time(padded[:, None], SIGMA_SECONDS * fps)[r:-r, 0]
    return torch.maximum(smooth, -clearance)  # smoothing must not put a foot back into the floor


def ground_motion(
    motion: Motion, probe: Motion, joints: list[int], rest: list[float], size: float = 1.0
) -> tuple[Motion, float]:
    """``motion`` moved vertically so the contact ``joints`` (rest heights ``rest``) stand on the floor
    as measured on ``probe`` (the same motion with every bone where it will end up: with the
    translations of bones under a floor armature) and decided by ``motion.foot_contacts`` (one column per
    joint, > 0.5 = down, believed within 2 ``HOVER``) or by a lowest joint within ``HOVER`` x ``size``
    (the rig's size) of its lowest level within ``BASELINE_SECONDS``.
    Returns the motion and the largest offset."""
    if not joints or motion.num_frames < 2:
        return motion, 0.0
    P = probe.positions
    clearance = (P[:, joints, 1] - torch.tensor(rest, dtype=P.dtype)).amin(1)
    fc = motion.foot_contacts
    w = max(1, round(BASELINE_SECONDS * motion.fps / 2))
    baseline = -torch.nn.functional.max_pool1d(-clearance[None, None], 2 * w + 1, stride=1, padding=w)[0, 0]
    down = clearance - baseline < HOVER * size
    if fc is not None and fc.shape[1] == len(joints):
        down |= (fc > 0.5).any(1) & (clearance - baseline < 2 * HOVER * size)
    off = ground_offsets(clearance, down, motion.fps).to(motion.root_translation.dtype)
    root = motion.root_translation.clone()
    root[:, 1] += off
    lt = motion.local_translations
    out = Motion(motion.skeleton, motion.fps, root, motion.local_rotations, motion.foot_contacts, lt)
    return out, float(off.abs().max())


def steady_height(motion: Motion, sigma_s: float = HEIGHT_SIGMA_SECONDS) -> tuple[Motion, float]:
    """``motion`` with its root height low-passed (Gaussian of ``sigma_s`` seconds, ends held); returns
    it and the largest change. Post-processing smooths the root's x/z and the rotations but leaves the
    height alone (a human run's bounce is detail); the any-rig model's height shakes instead: on the
    two-legged gun robot's attack, the vertical part was 70 % of every leg joint's jerk. Measured on
    232 training clips of the Quaternius build, 0.05 s moves the root height by 0.4 cm (median; 90th
    percentile 5 cm) of a 1-m rig."""
    if sigma_s <= 0 or motion.num_frames < 3:
        return motion, 0.0
    y = motion.root_translation[:, 1]
    r = int(3 * sigma_s * motion.fps) + 1
    padded = torch.cat([y[:1].expand(r), y, y[-1:].expand(r)])
    smooth = smooth_time(padded[:, None], sigma_s * motion.fps)[r:-r, 0]
    root = motion.root_translation.clone()
    root[:, 1] = smooth
    out = Motion(
        motion.skeleton, motion.fps, root, motion.local_rotations, motion.foot_contacts, motion.local_translations
    )
    return out, float((smooth - y).abs().max())


#: a translated foot's leg is the body joint nearest to it at rest, if within this (x rig size)
LEG_REACH = 0.3
SETTLE_SECONDS = 0.25
SETTLE_LIMIT = 0.3  # x rig size


def leg_ends(skeleton: Skeleton, feet: list[int], moved: list[int], size: float) -> list[tuple[int, int, float]]:
    """(foot, leg end, rest height of the leg end above the foot) for each foot bone moved by translation
    whose nearest body joint at rest (not moved by translation, not joint 0) is within ``LEG_REACH``."""
    R = rest_positions(skeleton).double()
    body = [j for j in range(1, skeleton.num_joints) if j not in set(moved)]
    out = []
    for h in feet:
        if not body:
            break
        dist = (R[body] - R[h]).norm(dim=-1)
        k = int(dist.argmin())
        if float(dist[k]) < LEG_REACH * size:
            out.append((h, body[k], float(R[body[k], 1] - R[h, 1])))
    return out


def settle_offsets(
    positions: torch.Tensor, legs: list[tuple[int, int, float]], fps: float, size: float
) -> torch.Tensor:
    """``(T,)`` how far the body stands too high above its feet: per frame, the median over ``legs`` of the
    leg end's height above its foot minus that height at rest, smoothed over ``SETTLE_SECONDS`` and held
    within ``SETTLE_LIMIT``. In the rigs' own clips this gap is close to 0 (median within 0.035 rig sizes
    on 18 of the 21 Quaternius rigs with translated feet: the engine's IK keeps legs on their feet); the
    shipped model's legs end 0.06-0.22 above where their feet are (quadrupeds, robots, dinosaurs) or
    0.15-0.21 below (humanoids), so after grounding by the feet the body floats, or sinks, off its legs."""
    P = positions.double()
    gaps = torch.stack([(P[:, e, 1] - P[:, h, 1]) - dy for h, e, dy in legs], 1)
    g = gaps.median(1).values
    r = int(3 * SETTLE_SECONDS * fps) + 1
    padded = torch.cat([g[:1].expand(r), g, g[-1:].expand(r)])
    smooth = smooth_time(padded[:, None], SETTLE_SECONDS * fps)[r:-r, 0]
    return smooth.clamp(-SETTLE_LIMIT * size, SETTLE_LIMIT * size)
