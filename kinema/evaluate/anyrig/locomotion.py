"""Does a generated creature move as its prompt and its rig's own clips say? (issue 34)

Measures of one motion on one rig, in the build's normalised units (the rest pose is 1 across, so
lengths are *body sizes*), for `kinema evaluate-anyrig`:

- `foot_gap_ratio`: the largest distance between a tied joint and its anchor (an IK foot bone and the
  leg chain's end, kinema.rig.ties) over the largest the rig's own clips show: > 1 tears the mesh;
- `ground_measures`: the root joint's ground path sampled every ``STRIDE_SECONDS`` (so frame-to-frame
  shaking does not count as travel): ``speed`` (path length / duration, body sizes/s), ``travel``
  (start to end), ``drift`` (largest distance from the start), ``forward_share`` (the path's component
  along the body's facing over its length: 1 = straight ahead, -1 = tail first, 0 = sideways or on the
  spot), ``net_turn_deg`` (heading at the end minus at the start, unwrapped, absolute) and
  ``total_turn_deg`` (summed absolute turning);
- `probe_prompts`: per action the rig's own clips show (idle, walk, run or gallop), the prompt the
  probe generates from: the caption of that action's first clip ("A fox gallops."), a walk asked to
  go forward ("A fox walks forward.", the issue's "walks forward" probe).

Facing is the heading of kinema.representation.joint (the rig's forward axis carried by its root).
"""

from __future__ import annotations

import math

import torch

from kinema.motion.core import Motion
from kinema.representation.joint import JointRepresentation
from kinema.rig.ties import RigTies, find_ties, tie_ratios

#: the root's ground path is sampled this often (seconds)
STRIDE_SECONDS = 0.25
#: clip contents (kinema.data.creature_captions) of each probed action, in order of preference
ACTIONS = {"idle": ("idle",), "walk": ("walk",), "run": ("gallop", "run")}


def rig_ties(rep: JointRepresentation, clips: list[Motion]) -> RigTies:
    """The ties of the rig from its own ``clips`` (one skeleton's: proportions differ between files)."""
    own = []
    for m in clips:
        G, P = m.to(torch.float64).global_transforms()
        own.append((P, G))
    return find_ties(rep.rig.skeleton, rep.rig.root, own)


def foot_gap_ratio(m: Motion, ties: RigTies) -> float | None:
    """Largest tie distance of ``m`` over the rig's own largest (None without ties)."""
    if not ties.ties:
        return None
    return float(tie_ratios(m.positions.to(torch.float64), ties.ties).max())


def ground_measures(m: Motion, rep: JointRepresentation) -> dict:
    """The ground path measures of ``m`` (see the module docstring)."""
    m = m.to(torch.float64)
    G, P = m.global_transforms()
    psi = rep.heading(G)
    step = max(1, round(STRIDE_SECONDS * m.fps))
    idx = list(range(0, m.num_frames, step))
    if idx[-1] != m.num_frames - 1:
        idx.append(m.num_frames - 1)
    xz = P[idx, rep.rig.root][:, [0, 2]]
    d = xz[1:] - xz[:-1]
    mid = torch.tensor(idx, dtype=torch.float64)
    # facing between two samples: the heading at the first of them, turned half the way to the second
    turn = torch.remainder(psi[idx[1:]] - psi[idx[:-1]] + math.pi, 2 * math.pi) - math.pi
    face = psi[idx[:-1]] + 0.5 * turn
    ahead = torch.stack([torch.sin(face), torch.cos(face)], dim=-1)
    length = float(d.norm(dim=-1).sum())
    rate = torch.remainder(psi[1:] - psi[:-1] + math.pi, 2 * math.pi) - math.pi  # per frame
    seconds = max(float(mid[-1] - mid[0]) / m.fps, 1e-9)
    return {
        "speed": length / seconds,
        "travel": float((xz[-1] - xz[0]).norm()),
        "drift": float((xz - xz[0]).norm(dim=-1).max()),
        "forward_share": float((d * ahead).sum()) / length if length > 1e-9 else 0.0,
        "net_turn_deg": abs(math.degrees(float(rate.sum()))),
        "total_turn_deg": math.degrees(float(rate.abs().sum())),
    }


def probe_prompts(contents: list[str], captions: list[str]) -> dict[str, str]:
    """Action -> prompt for the actions of `ACTIONS` that a rig's clips (``contents``, their first
    ``captions``) show; a walk caption "An X walks." becomes "An X walks forward."."""
    out = {}
    for action, names in ACTIONS.items():
        for name in names:
            if name in contents:
                cap = captions[contents.index(name)]
                if action == "walk" and cap.endswith(" walks."):
                    cap = cap[: -len(".")] + " forward."
                out[action] = cap
                break
    return out


def clip_speeds(clips: list[Motion], contents: list[str], rep: JointRepresentation) -> dict[str, float]:
    """Action -> mean ground speed (body sizes/s) of the rig's own clips of that action."""
    out = {}
    for action, names in ACTIONS.items():
        speeds = [ground_measures(m, rep)["speed"] for m, c in zip(clips, contents, strict=True) if c in names]
        if speeds:
            out[action] = sum(speeds) / len(speeds)
    return out
