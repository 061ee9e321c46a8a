"""Which joints and segments kinema.render draws, for any rig: helper roots are hidden, and parts that hang
from a hidden root (a creature's IK-driven feet) are joined to the body they belong to.

Positions ``P`` are ``(T, J, 3)`` metres, Y up.
"""

from __future__ import annotations

import numpy as np

from kinema import naming


def helper_root(sk, P: np.ndarray, pelvis: int) -> set[int]:
    """{0} when joint 0 is a helper root that is neither drawn nor framed, else an empty set.

    A helper root is away from the body (Bandai's joint_Root above the pelvis), or a control root on the
    ground carrying several separate parts (glTF creatures: an armature node or ``root`` bone holding the
    body and IK-driven feet): it never rises above the lowest other joint by more than 2 % of the pose size.
    """
    if sk.num_joints < 2:
        return set()
    if pelvis != 0:
        return {0}
    others = P[:, 1:]
    size = float(np.linalg.norm(others.max(1) - others.min(1), axis=-1).max())
    on_floor = (P[:, 0, 1] <= others[..., 1].min(1) + 0.02 * size).all()
    return {0} if len(sk.children[0]) > 1 and on_floor else set()


def drawn_bones(sk, P: np.ndarray, hidden: set[int]) -> list[tuple[int, int]]:
    """(parent, child) segments to draw: the hierarchy's bones below shown joints, plus, for parts hanging
    from a hidden root (IK feet of a creature), a segment to the nearest joint of the main body (of the same
    side when there is one) at frame 0."""
    bones = [(p, j) for j, p in enumerate(sk.parents) if p >= 0 and p not in hidden]
    if not hidden:
        return bones
    tops = list(sk.children[0])
    below = {t: {j for j in range(sk.num_joints) if t in sk.path_from_root(j)} for t in tops}
    body = max(tops, key=lambda t: len(below[t]))
    main = sorted(below[body])
    for t in tops:
        if t == body:
            continue
        side = naming.split_side(sk.names[t])[0]
        near = [j for j in main if naming.split_side(sk.names[j])[0] == side] or main  # a left foot to a left leg
        d = np.linalg.norm(P[0, near] - P[0, t], axis=-1)
        bones.append((near[int(d.argmin())], t))
    return bones
