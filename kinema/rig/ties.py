"""Joint ties: joints whose position a rig's own clips tie to another joint (IK foot bones, pole targets,
helpers), found from those clips.

Game rigs (all the Quaternius animals, dinosaurs, mechs and the knight) drive each foot with an *IK bone*
that hangs from the armature (``IKFrontLeg.L``, ``BackFoot.L``, ``Foot.L`` under ``AnimalArmature`` /
``root`` / ``RobotArmature``), positioned by translation; the engine's IK makes the leg chain reach it,
so in the rig's clips the foot stays at the leg chain's end. The skeleton does not say so (the foot is
not a child of the leg), so a generator that moves the two independently tears the mesh. A *tie* says
it from the clips:

- **candidates**: joints that hang from the *armature* (the joints at the top of the path to the rig's
  root that stand still in the clips: ``AnimalArmature``, a floor ``Root`` bone) without being on the
  path to the root, and every helper bone (``kinema.rig.find.
  HELPER_NAME``: pole, target, ctrl); i.e. everything positioned by something other than the body's
  joint rotations;
- **fixed** candidates: their position relative to their parent never changes in the clips (a static
  helper): they keep their rest offset and are never generated;
- **tied** candidates (every other one): the *anchor* is the joint the candidate keeps closest to over
  all clips (the smallest largest distance) among the joints outside its own subtree, outside the
  armature and outside other candidates' subtrees (a foot is tied to its leg, never to
  another foot). On the shared Quaternius files that is the lower leg for every IK foot (fox
  ``IKFrontLeg.L`` -> ``FrontLowerLeg.L``, largest distance 0.25 rig sizes; rat ``BackFoot.L`` ->
  ``BackLowLeg.L``, 0.19) and the chain's own foot joint where the rig has one (mech ``Foot.L`` ->
  ``FootBack.L``, 0.017). ``max_distance`` is the largest distance seen (the bound a generated motion
  must respect: the lower-leg -> foot gap), ``min_distance`` the smallest, ``offset`` the mean position
  of the joint in the anchor's frame (where the chain carries it) and ``spread`` the RMS distance from
  that mean (small for a real tie: 0.002-0.04 rig sizes for the IK feet, against 0.06-0.3 for the next
  best anchors).

API (positions ``(T, J, 3)``, global rotations ``(T, J, 4)`` wxyz, any units: the ties are in the units
of the clips; give one skeleton's clips, since files sharing a rig differ in proportions):

- ``find_ties(skeleton, root, clips) -> RigTies``: ``clips`` is a list of ``(positions, rotations)``
  (rotations may be ``None``: ``offset`` and ``spread`` are then left out as ``None``);
- ``RigTies.ties`` (list of `Tie`), ``RigTies.fixed`` (joint indices), ``RigTies.derived`` (every joint
  a generator must not produce freely: tied and fixed), ``RigTies.tie_for(joint)``;
- ``tie_distances(positions, ties) -> (T, len(ties))``: the joint -> anchor distance per frame;
  ``tie_ratios(positions, ties)`` the same over each tie's ``max_distance`` (the foot-to-leg gap as a
  multiple of the rig's own clips' largest: > 1 is further than the rig ever holds it);
- ``RigTies.to_dict(names)`` / ``RigTies.from_dict(d, names)``: JSON by joint name (checkpoints, caches);
- ``rest_ties(skeleton, root)``: a fallback for a rig with no clips, from its rest pose alone (anchor =
  nearest eligible joint at rest, ``max_distance`` = the rest distance);
- ``RigTies.scaled(factor)``: the same ties in other units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from kinema.geometry.rotations import quat_inverse, quat_rotate
from kinema.rig.find import helpers, rest_transforms
from kinema.skeleton import Skeleton

#: a candidate whose distance to its parent varies less than this (x rig size) in the clips is fixed
FIXED_TOL = 1e-4


@dataclass(frozen=True)
class Tie:
    """``joint`` stays within ``max_distance`` of ``anchor`` in the rig's clips (see the module)."""

    joint: int
    anchor: int
    max_distance: float
    min_distance: float
    offset: tuple[float, float, float] | None = None
    spread: float | None = None

    def to_dict(self, names: Sequence[str]) -> dict:
        d = {
            "joint": names[self.joint],
            "anchor": names[self.anchor],
            "max_distance": self.max_distance,
            "min_distance": self.min_distance,
        }
        if self.offset is not None:
            d["offset"], d["spread"] = list(self.offset), self.spread
        return d

    @classmethod
    def from_dict(cls, d: dict, names: Sequence[str]) -> Tie:
        index = {n: i for i, n in enumerate(names)}
        off = d.get("offset")
        return cls(
            index[d["joint"]],
            index[d["anchor"]],
            float(d["max_distance"]),
            float(d["min_distance"]),
            None if off is None else (float(off[0]), float(off[1]), float(off[2])),
            None if d.get("spread") is None else float(d["spread"]),
        )


@dataclass(frozen=True)
class RigTies:
    """The ties and fixed helpers of one skeleton (see the module)."""

    ties: list[Tie] = field(default_factory=list)
    fixed: tuple[int, ...] = ()

    @property
    def derived(self) -> tuple[int, ...]:
        """Joints a generator must not produce freely (tied or fixed), sorted."""
        return tuple(sorted({t.joint for t in self.ties} | set(self.fixed)))

    def scaled(self, factor: float) -> RigTies:
        """The same ties with every length multiplied by ``factor`` (metres <-> rig units)."""
        ties = [
            Tie(
                t.joint,
                t.anchor,
                t.max_distance * factor,
                t.min_distance * factor,
                None if t.offset is None else tuple(factor * x for x in t.offset),
                None if t.spread is None else t.spread * factor,
            )
            for t in self.ties
        ]
        return RigTies(ties, self.fixed)

    def tie_for(self, joint: int) -> Tie | None:
        return next((t for t in self.ties if t.joint == joint), None)

    def to_dict(self, names: Sequence[str]) -> dict:
        return {"ties": [t.to_dict(names) for t in self.ties], "fixed": [names[j] for j in self.fixed]}

    @classmethod
    def from_dict(cls, d: dict, names: Sequence[str]) -> RigTies:
        index = {n: i for i, n in enumerate(names)}
        return cls([Tie.from_dict(t, names) for t in d.get("ties", [])], tuple(index[n] for n in d.get("fixed", [])))


def _subtree(skeleton: Skeleton, joint: int) -> set[int]:
    out, stack = set(), [joint]
    while stack:
        k = stack.pop()
        out.add(k)
        stack.extend(skeleton.children[k])
    return out


def candidates(skeleton: Skeleton, root: int, armature: Sequence[int]) -> list[int]:
    """Joints positioned by something other than the body's rotations: children of the ``armature``
    joints (the static top of the path to ``root``) that are off that path, and helper bones (topmost of
    each helper subtree), sorted."""
    path = skeleton.path_from_root(root)
    above = set(armature)
    out = {j for j in range(skeleton.num_joints) if skeleton.parents[j] in above and j not in path}
    helper = helpers(skeleton)
    out |= {j for j in helper if skeleton.parents[j] not in helper and j not in path}
    return sorted(out)


def static_armature(
    skeleton: Skeleton, root: int, positions: torch.Tensor, rotations: torch.Tensor | None
) -> list[int]:
    """The joints at the top of the path to ``root`` that never turn in the clips and keep their place
    relative to the top joint (``positions (T, J, 3)``, ``rotations (T, J, 4)``): the armature / floor
    ``Root`` bones the body and the IK bones hang from. The top joint itself may travel (a clip given
    root motion moves the whole armature: kinema.data.root_motion)."""
    out = []
    path = skeleton.path_from_root(root)
    for j in path[:-1]:
        rel = positions[:, j] - positions[:, path[0]]
        still = float((rel - rel[0]).norm(dim=-1).max()) <= FIXED_TOL
        if rotations is not None:
            still = still and float((rotations[:, j] * rotations[:1, j]).sum(-1).abs().min()) >= 1 - 1e-6
        if not still:
            break
        out.append(j)
    return out


def rest_armature(skeleton: Skeleton, root: int, rest: torch.Tensor, band: float = 0.05) -> list[int]:
    """Without clips: the joints at the top of the path to ``root`` that lie on the floor at rest (within
    ``band`` x the rest pose's size of its lowest joint)."""
    size = float((rest.max(0).values - rest.min(0).values).max())
    low = float(rest[:, 1].min())
    out = []
    for j in skeleton.path_from_root(root)[:-1]:
        if float(rest[j, 1]) - low > band * size:
            break
        out.append(j)
    return out


def _eligible_anchors(skeleton: Skeleton, armature: Sequence[int], joint: int, cands: list[int]) -> list[int]:
    """Joints ``joint`` may be tied to: not in its subtree or any candidate's, not the armature."""
    banned = set(armature)
    for c in cands:
        banned |= _subtree(skeleton, c)
    return [a for a in range(skeleton.num_joints) if a not in banned and a != joint]


def find_ties(
    skeleton: Skeleton,
    root: int,
    clips: Sequence[tuple[torch.Tensor, torch.Tensor | None]],
) -> RigTies:
    """The ties and fixed helpers of ``skeleton`` from its clips ``[(positions (T, J, 3), rotations
    (T, J, 4) | None), ...]`` (global; see the module)."""
    if not clips:
        return RigTies()
    P = torch.cat([p.double() for p, _ in clips])
    have_rot = all(r is not None for _, r in clips)
    G = torch.cat([r.double() for _, r in clips]) if have_rot else None
    armature = static_armature(skeleton, root, P, G)
    cands = candidates(skeleton, root, armature)
    parents = skeleton.parents
    ties, fixed = [], []
    for j in cands:
        p = parents[j]
        d_parent = (P[:, j] - P[:, p]).norm(dim=-1) if p >= 0 else P[:, j].norm(dim=-1)
        local = quat_rotate(quat_inverse(G[:, p]), P[:, j] - P[:, p]) if (G is not None and p >= 0) else None
        moves = float(d_parent.max() - d_parent.min()) > FIXED_TOL
        if local is not None:
            moves = moves or float((local - local.mean(0)).norm(dim=-1).max()) > FIXED_TOL
        if not moves:
            fixed.append(j)
            continue
        anchors = _eligible_anchors(skeleton, armature, j, cands)
        if not anchors:
            continue
        dist = (P[:, j : j + 1] - P[:, anchors]).norm(dim=-1)  # (T, A)
        k = int(dist.amax(0).argmin())
        a = anchors[k]
        offset = spread = None
        if G is not None:
            loc = quat_rotate(quat_inverse(G[:, a]), P[:, j] - P[:, a])
            mean = loc.mean(0)
            offset = (float(mean[0]), float(mean[1]), float(mean[2]))
            spread = float((loc - mean).norm(dim=-1).pow(2).mean().sqrt())
        ties.append(Tie(j, a, float(dist[:, k].max()), float(dist[:, k].min()), offset, spread))
    return RigTies(ties, tuple(fixed))


def rest_ties(skeleton: Skeleton, root: int) -> RigTies:
    """Ties from the rest pose alone, for a rig with no clips (``root``: the rig's root joint): each
    candidate is tied to the nearest eligible joint at rest, ``max_distance`` = ``min_distance`` = that
    distance, ``offset`` its rest position in the anchor's frame (game rigs are posed with the IK solved:
    the foot at the shin's end); no candidate is fixed (nothing shows which ones move)."""
    G, rest = rest_transforms(skeleton)
    armature = rest_armature(skeleton, root, rest)
    cands = candidates(skeleton, root, armature)
    ties = []
    for j in cands:
        anchors = _eligible_anchors(skeleton, armature, j, cands)
        if not anchors:
            continue
        d = (rest[anchors] - rest[j]).norm(dim=-1)
        k = int(d.argmin())
        a = anchors[k]
        loc = quat_rotate(quat_inverse(G[a]), rest[j] - rest[a])
        ties.append(Tie(j, a, float(d[k]), float(d[k]), (float(loc[0]), float(loc[1]), float(loc[2])), 0.0))
    return RigTies(ties, ())


def tie_distances(positions: torch.Tensor, ties: Sequence[Tie]) -> torch.Tensor:
    """``(T, len(ties))``: each tie's joint -> anchor distance per frame of ``positions (T, J, 3)``."""
    if not ties:
        return positions.new_zeros(positions.shape[0], 0)
    j = [t.joint for t in ties]
    a = [t.anchor for t in ties]
    return (positions[:, j] - positions[:, a]).norm(dim=-1)


def tie_ratios(positions: torch.Tensor, ties: Sequence[Tie]) -> torch.Tensor:
    """``(T, len(ties))``: `tie_distances` over each tie's ``max_distance`` (> 1: further than the rig's
    own clips ever hold it)."""
    if not ties:
        return positions.new_zeros(positions.shape[0], 0)
    bound = torch.tensor([max(t.max_distance, 1e-9) for t in ties], dtype=positions.dtype)
    return tie_distances(positions, ties) / bound
