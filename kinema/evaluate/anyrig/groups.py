"""Held-out rigs by their similarity to an any-rig model's training rigs, and a table grouped by it.

Each rig gets a *shape*: its joint count, its number of legs and a canonical code of its joint tree.

- **tree code**: the rooted tree written canonically (AHU: a joint is ``(`` + its children's codes,
  sorted, + ``)``), so two skeletons have the same code exactly when one is the other with joints
  renamed and children reordered;
- **legs**: the rig layer's contact joints (kinema.rig, found from the skeleton alone), a contact
  below another contact counted once (heel + toe, an IK handle + its toe): 4 for the Quaternius
  quadrupeds, 2 for bipeds, 0 for fish, flyers and snakes.

A held-out rig is then, against the training rigs (first match wins):

- ``same topology``: a training rig has the same tree code (same skeleton, joints renamed);
- ``same topology +-1 joint``: removing one leaf joint from it, or from a training rig, gives the other's
  code (a gun or a tail tip added or removed);
- ``new topology``: no such rig, but a training rig has the same number of legs;
- ``new limb count``: no training rig has its number of legs.

``nearest`` names the training rig it was matched with (for the last two: among those with the same
or, failing that, the closest number of legs, the one with the closest joint count).
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass

from kinema.rig import Rig
from kinema.skeleton import Skeleton

CLASSES = ("same topology", "same topology +-1 joint", "new topology", "new limb count")


def tree_code(parents: list[int] | tuple[int, ...], drop: int | None = None) -> str:
    """Canonical code of the rooted tree ``parents`` (see the module docstring); ``drop`` leaves out one leaf."""
    kids: list[list[int]] = [[] for _ in parents]
    top = None
    for j, p in enumerate(parents):
        if j == drop:
            continue
        if p < 0:
            top = j
        else:
            kids[p].append(j)
    order, stack = [], [top]
    while stack:  # parents before children, without recursion (deep chains: snakes, tails)
        j = stack.pop()
        order.append(j)
        stack += kids[j]
    code: dict[int, str] = {}
    for j in reversed(order):
        code[j] = "(" + "".join(sorted(code[k] for k in kids[j])) + ")"
    return code[top]


def leg_count(rig: Rig) -> int:
    """Contact joints without a contact joint above them (see the module docstring)."""
    contacts = set(rig.contacts)
    return sum(1 for j in contacts if not contacts.intersection(rig.skeleton.path_from_root(j)[:-1]))


@dataclass(frozen=True)
class RigShape:
    """What `classify` compares: the rig id, joints, legs, tree code and codes with one leaf removed."""

    rig: str
    joints: int
    legs: int
    code: str
    minus_leaf: frozenset[str]


def rig_shape(rig_id: str, skeleton: Skeleton) -> RigShape:
    """The shape of one rig (contacts from kinema.rig.Rig.from_skeleton, as at generation time)."""
    parents = list(skeleton.parents)
    leaves = [j for j, c in enumerate(skeleton.children) if not c and parents[j] >= 0]
    return RigShape(
        rig_id,
        skeleton.num_joints,
        leg_count(Rig.from_skeleton(skeleton)),
        tree_code(parents),
        frozenset(tree_code(parents, drop=j) for j in leaves),
    )


def training_shapes(train_rigs: dict) -> list[RigShape]:
    """Shapes of a model's training rigs (``LoadedAnyRig.train_rigs``: rig id -> rig dict)."""
    return [rig_shape(rid, Skeleton.from_dict(d["skeleton"])) for rid, d in sorted(train_rigs.items())]


def classify(shape: RigShape, train: list[RigShape]) -> tuple[str, str | None]:
    """(class, nearest training rig id) of ``shape`` against the training rigs ``train`` (module docstring)."""
    others = [t for t in train if t.rig != shape.rig]
    if not others:
        return CLASSES[3], None
    for t in others:
        if t.code == shape.code:
            return CLASSES[0], t.rig
    for t in others:
        if shape.code in t.minus_leaf or t.code in shape.minus_leaf:
            return CLASSES[1], t.rig
    legs = min({t.legs for t in others}, key=lambda n: abs(n - shape.legs))
    pool = [t for t in others if t.legs == legs]
    nearest = min(pool, key=lambda t: (abs(t.joints - shape.joints), t.rig)).rig
    return (CLASSES[2] if legs == shape.legs else CLASSES[3]), nearest


def _median(values) -> str:
    vs = [v for v in values if v is not None]
    return f"{statistics.median(vs):.2f}" if vs else "-"


def _ratio(r: dict, key: str) -> float | None:
    ref = r.get(f"{key}_ref")
    return None if not ref or r.get(key) is None else r[key] / ref


def similarity_table(rows: list[dict]) -> str:
    """Markdown table of the held-out rows (with a ``similarity``) grouped by class: rigs, medians of
    the skate and jerk ratios to the rigs' own clips, constraint error and caption retrieval R@1."""
    out = [
        "| similarity to training rigs | rigs | median skate ratio | median jerk ratio | median constraint cm "
        "| retrieval R@1 (chance) |",
        "|" + "---|" * 6,
    ]
    for cls in CLASSES:
        group = [r for r in rows if r.get("similarity") == cls]
        if not group:
            continue
        hits = sum(r["retrieval_hits"] for r in group if r.get("retrieval_hits") is not None)
        tries = sum(r["retrieval_n"] for r in group if r.get("retrieval_n"))
        chance = sum(r["retrieval_chance"] * r["retrieval_n"] for r in group if r.get("retrieval_n"))
        retrieval = f"{hits / tries:.2f} ({chance / tries:.2f})" if tries else "-"
        names = ", ".join(r["rig"] for r in group)
        out.append(
            f"| {cls} ({names}) | {len(group)} | {_median(r.get('skate_ratio') for r in group)} "
            f"| {_median(_ratio(r, 'jerk') for r in group)} | {_median(r.get('constraint_cm') for r in group)} "
            f"| {retrieval} |"
        )
    return "\n".join(out)


def _max(values) -> str:
    vs = [v for v in values if v is not None]
    return f"{max(vs):.2f}" if vs else "-"


def split_summary(rows: list[dict]) -> str:
    """Markdown table of medians over the rigs of each split (skate and jerk as ratios to the rigs' own
    clips, rigs whose skate is within 2x of their own clips'), the constraint errors (median and
    worst), the largest bone stretch and the caption retrieval hits."""
    out = [
        "| split | rigs | median skate ratio | skate within 2x | median jerk ratio | joint target cm (median / max) "
        "| rotation target deg (max) | keyframe cm (max) | stretch (max) | retrieval hits |",
        "|" + "---|" * 10,
    ]
    for split in dict.fromkeys(r["split"] for r in rows):
        group = [r for r in rows if r["split"] == split]
        ratios = [r["skate_ratio"] for r in group if r.get("skate_ratio") is not None]
        hits = sum(r.get("retrieval_hits") or 0 for r in group)
        tries = sum(r.get("retrieval_n") or 0 for r in group)
        out.append(
            f"| {split} | {len(group)} | {_median(ratios)} | {sum(x <= 2 for x in ratios)} of {len(ratios)} "
            f"| {_median(_ratio(r, 'jerk') for r in group)} "
            f"| {_median(r.get('constraint_cm') for r in group)} / {_max(r.get('constraint_cm') for r in group)} "
            f"| {_max(r.get('constraint_deg') for r in group)} | {_max(r.get('keyframe_cm') for r in group)} "
            f"| {max(r['stretch'] for r in group):.1e} | {hits} of {tries} |"
        )
    return "\n".join(out)
