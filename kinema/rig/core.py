"""`Rig`: a skeleton with the parts motion generation needs to know about.

- ``root``: the joint whose position is the character's position (the pelvis of a human; not
  necessarily joint 0, which may be a static helper above it);
- ``up`` / ``forward``: unit axes of the rig's canonical frame (kinema: Y up, +Z forward);
- ``contacts``: joints that touch the ground, any number (human: [left ankle, left toe, right ankle,
  right toe], the 4 contact channels [L heel, L toe, R heel, R toe]; a fish: none) — a motion's
  ``foot_contacts`` is ``(T, len(contacts))``;
- ``end_effectors``: name -> joint (``left_hand``, ...; creatures: leaf joints by name);
- ``limbs``: name -> chain of joints from the root side to the end (``left_leg``: hip..toe).

Build one with ``Rig.from_skeleton(skeleton, overrides=path_or_mapping)``: parts are found from joint
names, else from the rest-pose geometry (kinema.rig.find), then replaced by the overrides
(kinema.rig.overrides). ``to_dict`` / ``from_dict`` store joints by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from kinema.errors import SkeletonError
from kinema.rig import find
from kinema.rig import overrides as ov
from kinema.skeleton import Skeleton

Y_UP = (0.0, 1.0, 0.0)
Z_FORWARD = (0.0, 0.0, 1.0)
RIG_KEYS = ("skeleton", *ov.OVERRIDE_KEYS)


@dataclass(frozen=True, eq=False, kw_only=True)
class Rig:
    """A skeleton and its root, axes, contact joints, end effectors and limb chains (see module)."""

    skeleton: Skeleton
    root: int
    up: tuple[float, float, float] = Y_UP
    forward: tuple[float, float, float] = Z_FORWARD
    contacts: tuple[int, ...] = ()
    end_effectors: Mapping[str, int] = field(default_factory=dict)
    limbs: Mapping[str, tuple[int, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        J = self.skeleton.num_joints
        every = [
            ("root", self.root),
            *(("contacts", j) for j in self.contacts),
            *((f"end_effectors.{k}", j) for k, j in self.end_effectors.items()),
            *((f"limbs.{k}", j) for k, c in self.limbs.items() for j in c),
        ]
        for where, j in every:
            if not (isinstance(j, int) and 0 <= j < J):
                raise SkeletonError(f"rig {where}: joint {j!r} is not an index in 0..{J - 1}")
        if len(set(self.contacts)) != len(self.contacts):
            raise SkeletonError(f"rig contacts repeat a joint: {self.joint_names(self.contacts)}")
        for name, chain in self.limbs.items():
            if len(chain) < 2 or any(self.skeleton.parents[b] != a for a, b in zip(chain, chain[1:], strict=False)):
                raise SkeletonError(
                    f"rig limb {name!r} {self.joint_names(chain)} is not a parent-to-child chain of two or more joints"
                )
        if abs(sum(u * f for u, f in zip(self.up, self.forward, strict=True))) > 1e-6:
            raise SkeletonError(f"rig up {self.up} and forward {self.forward} must be perpendicular")

    # ------------------------------------------------------------------ building
    @classmethod
    def from_skeleton(cls, skeleton: Skeleton, *, overrides: str | Path | Mapping | None = None) -> Rig:
        """Find the parts from names (else geometry), then apply ``overrides`` (a JSON path or mapping)."""
        over, source = ov.read_overrides(overrides)
        roles = skeleton.roles
        if "root" in over:
            root = ov.joint(skeleton, over["root"], source, "root")
        else:
            root = roles["pelvis"] if "pelvis" in roles else find.geometric_root(skeleton)
        contacts = find.named_contacts(skeleton)
        limbs = find.named_limbs(skeleton)
        effectors = find.named_effectors(skeleton)
        if contacts is None:
            feet = find.geometric_feet(skeleton, root)
            contacts = find.geometric_contacts(skeleton, feet, root)
            limbs = {**limbs, **find.geometric_limbs(skeleton, feet, root)}
            effectors = effectors or find.leaf_effectors(skeleton, root, set())
        return cls(
            skeleton=skeleton,
            root=root,
            up=ov.axis(over["up"], source, "up") if "up" in over else Y_UP,
            forward=ov.axis(over["forward"], source, "forward") if "forward" in over else Z_FORWARD,
            contacts=ov.joints(skeleton, over["contacts"], source, "contacts") if "contacts" in over else contacts,
            end_effectors=(
                ov.named_joints(skeleton, over["end_effectors"], source, "end_effectors")
                if "end_effectors" in over
                else effectors
            ),
            limbs=ov.named_chains(skeleton, over["limbs"], source, "limbs") if "limbs" in over else limbs,
        )

    # ------------------------------------------------------------------ queries
    @property
    def num_joints(self) -> int:
        return self.skeleton.num_joints

    @property
    def num_contacts(self) -> int:
        return len(self.contacts)

    def joint_names(self, joints) -> list[str]:
        return [self.skeleton.names[j] for j in joints]

    @property
    def contact_mirror(self) -> list[int]:
        """For each contact channel, the channel of its left/right partner (itself for centre joints)."""
        where = {j: i for i, j in enumerate(self.contacts)}
        return [where.get(self.skeleton.mirror_map[j], i) for i, j in enumerate(self.contacts)]

    def legs(self) -> dict[str, tuple[int, ...]]:
        """Limbs that end in (or contain) a contact joint: the chains foot locking and IK work on."""
        cs = set(self.contacts)
        return {k: c for k, c in self.limbs.items() if cs.intersection(c)}

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        """JSON-friendly: the skeleton and every part by joint name."""
        return {
            "skeleton": self.skeleton.to_dict(),
            "root": self.skeleton.names[self.root],
            "up": list(self.up),
            "forward": list(self.forward),
            "contacts": self.joint_names(self.contacts),
            "end_effectors": {k: self.skeleton.names[j] for k, j in self.end_effectors.items()},
            "limbs": {k: self.joint_names(c) for k, c in self.limbs.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping, *, skeleton: Skeleton | None = None) -> Rig:
        """Inverse of :meth:`to_dict` (``skeleton`` given explicitly when ``d`` has none); every part
        given is kept, missing ones are found as in :meth:`from_skeleton`; unknown keys raise."""
        if not isinstance(d, Mapping):
            raise SkeletonError(f"a rig description is a JSON object, got {type(d).__name__}")
        unknown = sorted(set(d) - set(RIG_KEYS))
        if unknown:
            raise SkeletonError(f"rig description: unknown keys {unknown}; expected some of {list(RIG_KEYS)}")
        if skeleton is None:
            if "skeleton" not in d:
                raise SkeletonError("rig description lacks field 'skeleton'")
            skeleton = Skeleton.from_dict(d["skeleton"])
        return cls.from_skeleton(skeleton, overrides={k: v for k, v in d.items() if k != "skeleton"})

    def __repr__(self) -> str:
        return (
            f"Rig({self.skeleton!r}, root {self.skeleton.names[self.root]}, {len(self.contacts)} contacts, "
            f"limbs {list(self.limbs)})"
        )
