"""Left/right mirroring of motions on skeletons whose rest pose need not be symmetric.

The mirror image reflects the world through the YZ plane (x -> -x) and swaps left/right joints.
Positions simply reflect, ``x'_{m(j)} = M x_j`` with ``M = diag(-1, 1, 1)``. Rotations need care:
many rigs (Bandai Namco's among them) have rest frames that are not mirror images of each other,
so the mirrored global rotation is ``G'_{m(j)} = (M G_j M) B_j`` where the constant correction
``B_j`` maps the partner's bone offsets onto the reflected own offsets: ``B_j o_{m(c)} = M o_c`` for
the children ``c`` of ``j``. It is solved once per skeleton (Kabsch for several children; for one child
the rotation nearest the parent's correction; leaves inherit their parent's), which makes mirroring
exact on positions and an involution (mirroring twice is the identity).
"""

from __future__ import annotations

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import matrix_to_quat, mirror_quat_x, quat_between, quat_mul, quat_rotate
from kinema.skeleton import Skeleton

_M = torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)

#: foot contact channels [L heel, L toe, R heel, R toe] after mirroring
CONTACT_MIRROR = [2, 3, 0, 1]


def _kabsch(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor | None:
    """Rotation matrix R minimising sum |R a_i - b_i|^2, or None when the points are (near) collinear."""
    H = a.T @ b  # (3, 3)
    U, S, Vh = torch.linalg.svd(H)
    if S[1] < 1e-6 * max(S[0].item(), 1e-12):
        return None
    d = torch.sign(torch.det(Vh.T @ U.T))
    D = torch.diag(torch.tensor([1.0, 1.0, d.item()], dtype=torch.float64))
    return Vh.T @ D @ U.T


def mirror_corrections(skeleton: Skeleton) -> torch.Tensor:
    """(J, 4) float64 quaternions B_j (see the module docstring)."""
    mmap = skeleton.mirror_map
    J = skeleton.num_joints
    B = torch.zeros(J, 4, dtype=torch.float64)
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64)
    for j in range(J):
        parent_b = B[skeleton.parents[j]] if skeleton.parents[j] >= 0 else identity
        kids = [c for c in skeleton.children[j] if skeleton.offsets[c].norm() > 1e-9]
        a = torch.stack([skeleton.offsets[mmap[c]] for c in kids]) if kids else None
        b = torch.stack([skeleton.offsets[c] * _M for c in kids]) if kids else None
        rot = _kabsch(a, b) if kids and len(kids) > 1 else None
        if rot is not None:
            B[j] = matrix_to_quat(rot)
        elif kids:
            # one child (or collinear children): the rotation closest to the parent's correction
            start = quat_rotate(parent_b, a[0])
            B[j] = quat_mul(quat_between(start, b[0]), parent_b)
        else:
            B[j] = parent_b
    return B


def mirror_motion(motion, contact_map: list[int] | None = None):
    """The mirror image of ``motion`` (a kinema Motion) on the same skeleton.

    Contact channels are swapped left <-> right with ``contact_map`` (channel i of the result is channel
    ``contact_map[i]`` of the input); the default fits the human rig's 4 channels [L heel, L toe, R heel,
    R toe]. Other rigs pass their own (kinema.rig.Rig.contact_mirror)."""
    skel = motion.skeleton
    mmap = list(skel.mirror_map)
    G, _ = motion.global_transforms()
    B = mirror_corrections(skel).to(G.dtype)
    # G'[m(j)] = mirror(G[j]) * B[j]  ->  gather: G'[k] = mirror(G[m(k)]) * B[m(k)]
    G_new = quat_mul(mirror_quat_x(G[:, mmap]), B[mmap])
    root = motion.root_translation * _M.to(G.dtype)
    contacts = motion.foot_contacts
    if contacts is not None:
        if contact_map is None and contacts.shape[1] != len(CONTACT_MIRROR):
            raise KinemaError(
                f"mirroring {contacts.shape[1]} contact channels needs a contact_map (kinema.rig.Rig.contact_mirror)"
            )
        contacts = contacts[:, CONTACT_MIRROR if contact_map is None else list(contact_map)]
    positions = None
    if motion.local_translations is not None:  # animated bones: reflect the positions and solve translations
        positions = motion.positions[:, mmap] * _M.to(G.dtype)
    return type(motion).from_global(skel, motion.fps, root, G_new, contacts, positions)
