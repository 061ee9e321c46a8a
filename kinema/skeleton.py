"""Skeletons: joint tree, rest offsets, semantic roles, mirror pairs, pruning and tree info.

Nothing here assumes a particular rig: roles (pelvis, hands, feet, ...) are found by name across the
common naming schemes (Bandai ``UpperLeg_L``, Mixamo/CMU ``LeftUpLeg``, 3ds Max ``Bip01 L Thigh``,
``mixamorig:`` prefixes, Blender ``.L``/``_l`` suffixes) and can be overridden explicitly.

Shapes and units: offsets ``(J, 3)`` in metres (child position in the parent frame at rest),
rest rotations ``(J, 4)`` quaternions ``(w, x, y, z)``; parents come before children, root parent -1.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import torch

from kinema import naming
from kinema.errors import SkeletonError

if TYPE_CHECKING:
    from kinema.mesh import SkinnedMesh

#: Roles every locomotion feature needs (see kinema.representation.kimodo_features).
LOCOMOTION_ROLES = ("pelvis", "left_hip", "right_hip", "left_ankle", "right_ankle", "left_toe", "right_toe")


@dataclass(eq=False)
class Skeleton:
    """A kinematic tree of named joints with rest offsets (metres) and optional rest rotations."""

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: torch.Tensor  # (J, 3) float64, metres
    rest_rotations: torch.Tensor | None = None  # (J, 4) wxyz local rest/bind rotations
    end_sites: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    role_overrides: dict[str, str] = field(default_factory=dict)
    name: str = ""
    mesh: SkinnedMesh | None = None  # the rig's skin (from a GLB), carried to written GLBs; not serialised

    def __init__(
        self,
        names: Sequence[str],
        parents: Sequence[int],
        offsets,
        rest_rotations=None,
        end_sites: Mapping[int, Sequence[float]] | None = None,
        role_overrides: Mapping[str, str] | None = None,
        name: str = "",
        mesh: SkinnedMesh | None = None,
    ):
        self.names = tuple(str(n) for n in names)
        self.parents = tuple(int(p) for p in parents)
        self.offsets = torch.as_tensor(offsets, dtype=torch.float64).clone().reshape(-1, 3)
        self.rest_rotations = (
            None if rest_rotations is None else torch.as_tensor(rest_rotations, dtype=torch.float64).reshape(-1, 4)
        )
        self.end_sites = {int(k): tuple(float(x) for x in v) for k, v in (end_sites or {}).items()}
        self.role_overrides = dict(role_overrides or {})
        self.name = name
        self.mesh = mesh
        self._validate()

    # ------------------------------------------------------------------ validation and basics
    def _validate(self) -> None:
        J = len(self.names)
        if J == 0:
            raise SkeletonError("a skeleton needs at least one joint")
        if len(set(self.names)) != J:
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise SkeletonError(f"duplicate joint names: {dup}")
        if len(self.parents) != J:
            raise SkeletonError(f"{len(self.parents)} parents for {J} joints")
        if self.offsets.shape != (J, 3):
            raise SkeletonError(f"offsets have shape {tuple(self.offsets.shape)}, expected ({J}, 3)")
        if self.rest_rotations is not None and self.rest_rotations.shape != (J, 4):
            raise SkeletonError(f"rest_rotations have shape {tuple(self.rest_rotations.shape)}, expected ({J}, 4)")
        if self.parents[0] != -1:
            raise SkeletonError(f"joint 0 ({self.names[0]}) must be the root (parent -1)")
        for j, p in enumerate(self.parents[1:], start=1):
            if not 0 <= p < j:
                raise SkeletonError(
                    f"joint {j} ({self.names[j]}) has parent {p}: parents must be listed before children"
                )
        if not torch.isfinite(self.offsets).all():
            raise SkeletonError("offsets contain NaN or inf")
        if self.mesh is not None and self.mesh.max_joint() >= J:
            raise SkeletonError(f"mesh is skinned to joint {self.mesh.max_joint()} but the skeleton has {J} joints")
        for role, joint in self.role_overrides.items():
            if joint not in self.names:
                raise SkeletonError(f"role override {role!r} names unknown joint {joint!r}")

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of a joint by exact name, or of a role (``left_hand``, ``pelvis``...)."""
        if name in self._name_to_index:
            return self._name_to_index[name]
        roles = self.roles
        role = naming.ROLE_ALIASES.get(name, name)
        if role in roles:
            return roles[role]
        raise SkeletonError(f"unknown joint or role {name!r}; joints are {list(self.names)}")

    @cached_property
    def _name_to_index(self) -> dict[str, int]:
        return {n: i for i, n in enumerate(self.names)}

    def same_topology(self, other: Skeleton) -> bool:
        """True when both skeletons have the same joint names and parents (offsets may differ)."""
        return self.names == other.names and self.parents == other.parents

    # ------------------------------------------------------------------ tree info
    @cached_property
    def children(self) -> tuple[tuple[int, ...], ...]:
        kids: list[list[int]] = [[] for _ in self.names]
        for j, p in enumerate(self.parents):
            if p >= 0:
                kids[p].append(j)
        return tuple(tuple(k) for k in kids)

    @cached_property
    def depths(self) -> tuple[int, ...]:
        """Number of edges from the root to each joint."""
        d = [0] * self.num_joints
        for j, p in enumerate(self.parents):
            if p >= 0:
                d[j] = d[p] + 1
        return tuple(d)

    def path_from_root(self, joint: int | str) -> list[int]:
        """Joint indices from the root down to ``joint`` (inclusive)."""
        j = self.index(joint) if isinstance(joint, str) else int(joint)
        path = []
        while j >= 0:
            path.append(j)
            j = self.parents[j]
        return path[::-1]

    @cached_property
    def ancestor_matrix(self) -> torch.Tensor:
        """(J, J) float64 with A[j, k] = 1 when k is j itself or an ancestor of j other than the root.

        Joint positions are ``root + A @ bone_vectors`` where bone_vectors[k] is joint k's offset
        rotated into the world; this lets FK from global rotations run without a Python loop.
        """
        A = torch.zeros(self.num_joints, self.num_joints, dtype=torch.float64)
        for j in range(self.num_joints):
            for k in self.path_from_root(j)[1:]:
                A[j, k] = 1.0
        return A

    def tree_distances(self) -> torch.Tensor:
        """(J, J) number of edges between every pair of joints (for tree positional encodings)."""
        J = self.num_joints
        depth = torch.tensor(self.depths)
        paths = [set(self.path_from_root(j)) for j in range(J)]
        dist = torch.zeros(J, J, dtype=torch.long)
        for a in range(J):
            for b in range(a + 1, J):
                common = max((depth[k].item() for k in paths[a] & paths[b]), default=0)
                dist[a, b] = dist[b, a] = depth[a] + depth[b] - 2 * common
        return dist

    # ------------------------------------------------------------------ roles and mirroring
    @cached_property
    def roles(self) -> dict[str, int]:
        """Semantic role -> joint index, found by name (see kinema.naming) plus explicit overrides."""
        found = naming.find_roles(self.names, self.depths)
        for role, joint in self.role_overrides.items():
            found[naming.ROLE_ALIASES.get(role, role)] = self._name_to_index[joint]
        return found

    def require_roles(self, roles: Sequence[str]) -> dict[str, int]:
        """Roles that must exist (e.g. for motion features); raises naming the missing ones."""
        have = self.roles
        missing = [r for r in roles if naming.ROLE_ALIASES.get(r, r) not in have]
        if missing:
            raise SkeletonError(
                f"skeleton {self.name or '(unnamed)'} has no joint for roles {missing}; "
                f"pass role_overrides={{role: joint_name}} (joints: {list(self.names)})"
            )
        return {r: have[naming.ROLE_ALIASES.get(r, r)] for r in roles}

    @cached_property
    def mirror_map(self) -> tuple[int, ...]:
        """For each joint, the index of its left/right partner (itself for centre joints)."""
        out = []
        for j, n in enumerate(self.names):
            partner = naming.swap_side(n)
            out.append(self._name_to_index.get(partner, j) if partner else j)
        return tuple(out)

    @property
    def mirror_pairs(self) -> list[tuple[int, int]]:
        """(left, right) index pairs, each once."""
        return [(j, m) for j, m in enumerate(self.mirror_map) if m > j]

    # ------------------------------------------------------------------ editing
    def prune(self, drop: Sequence[str], fold_rotations: torch.Tensor | None = None) -> tuple[Skeleton, list[int]]:
        """Remove joints, re-attaching their children to the nearest kept ancestor.

        A removed joint's offset (and local rotation: ``fold_rotations`` (J, 4), defaulting to the rest
        rotations) is folded into its children's offsets, so the kept joints keep their rest positions.
        Returns the new skeleton and the kept joint indices (in the old numbering). Dropping the root
        makes its single child the new root (more than one child would leave a forest: an error).
        """
        drop_idx = {self.index(n) for n in drop}
        keep = [j for j in range(self.num_joints) if j not in drop_idx]
        if not keep:
            raise SkeletonError("cannot prune every joint")
        rots = fold_rotations if fold_rotations is not None else self.rest_rotations
        new_offsets, new_parents = [], []
        old_to_new = {old: new for new, old in enumerate(keep)}
        from kinema.geometry.rotations import quat_mul, quat_rotate  # local import: keep module import light

        for j in keep:
            offset = self.offsets[j].clone()
            p = self.parents[j]
            while p >= 0 and p in drop_idx:
                if rots is not None:
                    offset = quat_rotate(rots[p].to(offset), offset)
                offset = self.offsets[p] + offset
                p = self.parents[p]
            new_parents.append(old_to_new[p] if p >= 0 else -1)
            new_offsets.append(offset)
        if sum(1 for p in new_parents if p < 0) != 1 or new_parents[0] != -1:
            raise SkeletonError(f"pruning {sorted(drop)} would leave more than one root")
        new_rest = None
        if self.rest_rotations is not None:
            new_rest = self.rest_rotations[keep].clone()
            # a new root inherits the rest rotations of the dropped ancestors above it
            chain = [a for a in self.path_from_root(keep[0])[:-1] if a in drop_idx]
            for a in reversed(chain):
                new_rest[0] = quat_mul(self.rest_rotations[a], new_rest[0])
        overrides = {r: n for r, n in self.role_overrides.items() if self.index(n) in old_to_new}
        ends = {old_to_new[j]: v for j, v in self.end_sites.items() if j in old_to_new}
        # the skin stays valid when the rest pose is unchanged (folding rest rotations) and no weighted joint goes
        same_rest = fold_rotations is None or (
            self.rest_rotations is not None and torch.allclose(fold_rotations.double(), self.rest_rotations)
        )
        mesh = self.mesh.remap_joints(keep) if self.mesh is not None and same_rest else None
        new = Skeleton(
            [self.names[j] for j in keep],
            new_parents,
            torch.stack(new_offsets),
            new_rest,
            ends,
            overrides,
            self.name,
            mesh,
        )
        return new, keep

    def reach(self) -> float:
        """Length of the longest root-to-joint chain of rest offsets (the skeleton's units; an upper bound on
        the rig's half-size that needs no forward kinematics)."""
        lengths = [0.0] * self.num_joints
        norms = self.offsets.double().norm(dim=-1).tolist()
        for j, p in enumerate(self.parents):
            if p >= 0:
                lengths[j] = lengths[p] + norms[j]
        return max(lengths, default=0.0)

    def scaled(self, factor: float) -> Skeleton:
        """The same skeleton with every length multiplied by ``factor``."""
        ends = {j: tuple(factor * x for x in v) for j, v in self.end_sites.items()}
        mesh = None if self.mesh is None else self.mesh.scaled(factor)
        return Skeleton(
            self.names,
            self.parents,
            self.offsets * factor,
            self.rest_rotations,
            ends,
            self.role_overrides,
            self.name,
            mesh,
        )

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        """JSON-friendly description, saved next to model weights."""
        return {
            "name": self.name,
            "names": list(self.names),
            "parents": list(self.parents),
            "offsets": self.offsets.tolist(),
            "rest_rotations": None if self.rest_rotations is None else self.rest_rotations.tolist(),
            "end_sites": {str(k): list(v) for k, v in self.end_sites.items()},
            "role_overrides": dict(self.role_overrides),
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> Skeleton:
        try:
            return cls(
                d["names"],
                d["parents"],
                d["offsets"],
                d.get("rest_rotations"),
                {int(k): v for k, v in d.get("end_sites", {}).items()},
                d.get("role_overrides", {}),
                d.get("name", ""),
            )
        except KeyError as err:
            raise SkeletonError(f"skeleton description lacks field {err}") from None

    def __repr__(self) -> str:
        return f"Skeleton({self.name or 'unnamed'}, {self.num_joints} joints)"


def side_contacts(roles: dict[str, int], side: str) -> tuple[int, int] | None:
    """(heel, toe) joint indices of one side (the ankle stands in for a missing heel), or None."""
    heel = roles.get(f"{side}_heel", roles.get(f"{side}_ankle"))
    toe = roles.get(f"{side}_toe")
    return None if heel is None or toe is None else (heel, toe)
