"""Kimodo motion features (paper Sec. 4.1) and the local root representation (Sec. 4.2).

Per frame, for a skeleton of J joints, the feature vector (dimension ``5 + 12 J + 4``) is
``[r_p (3), r_a (2), j_p (3J), j_v (3J), j_a (6J), f (4)]``:

- ``r_p`` smoothed global root: pelvis x/z Gaussian-smoothed (see kinema.motion.smoothing), pelvis y kept;
- ``r_a`` heading ``(cos psi, sin psi)`` of ``e_y x (right_hip - left_hip)`` projected on the ground;
- ``j_p`` joint positions: x/z relative to the smoothed root, y global (not heading-canonicalised);
- ``j_v`` global joint velocities in m/s (forward differences, the last frame repeats the previous);
- ``j_a`` global joint rotations, 6D (first two matrix columns);
- ``f`` foot contacts [L heel, L toe, R heel, R toe] in {0, 1}.

The global root is ``[r_p, r_a]`` (5 numbers) and the body is the rest. Features -> Motion uses only
``j_p`` of the pelvis (the root translation) and ``j_a`` (rotations, then FK), so a round trip
reproduces joint positions up to float precision. Shapes: features ``(..., T, D)``, metres, seconds.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import quat_to_sixd, sixd_to_quat
from kinema.motion.contacts import ContactThresholds, foot_contacts
from kinema.motion.core import Motion
from kinema.motion.heading import heading_from_positions
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton


def motion_to_features(
    motion: Motion,
    root_sigma: float = DEFAULT_ROOT_SIGMA_SECONDS,
    thresholds: ContactThresholds | None = None,
) -> torch.Tensor:
    """Kimodo features ``(T, 5 + 12 J + 4)`` of a motion (float32 unless the motion is float64)."""
    skel = motion.skeleton
    pelvis = skel.require_roles(["pelvis"])["pelvis"]
    G, P = motion.global_transforms()
    T = motion.num_frames
    root = P[:, pelvis].clone()
    root[:, [0, 2]] = smooth_time(P[:, pelvis][:, [0, 2]], root_sigma * motion.fps)
    heading = heading_from_positions(P, skel)
    jp = P.clone()
    jp[..., 0] -= root[:, None, 0]
    jp[..., 2] -= root[:, None, 2]
    vel = torch.zeros_like(P)
    if T > 1:
        vel[:-1] = (P[1:] - P[:-1]) * motion.fps
        vel[-1] = vel[-2]
    rot6 = quat_to_sixd(G)
    if motion.foot_contacts is not None:
        contacts = (motion.foot_contacts > 0.5).to(P.dtype)
    else:
        contacts = foot_contacts(P, motion.fps, skel, thresholds or ContactThresholds())
    return torch.cat(
        [root, heading, jp.flatten(-2), vel.flatten(-2), rot6.flatten(-2), contacts], dim=-1
    )


def features_to_motion(features: torch.Tensor, skeleton: Skeleton, fps: float) -> Motion:
    """Motion from features (T, D): pelvis position from ``j_p`` + root, rotations from ``j_a``, then FK."""
    layout = FeatureLayout(skeleton.num_joints)
    if features.shape[-1] != layout.dim:
        raise ValueError(f"features have {features.shape[-1]} channels, expected {layout.dim}")
    parts = layout.split(features)
    pelvis = skeleton.require_roles(["pelvis"])["pelvis"]
    if pelvis != 0:
        raise ValueError("features_to_motion needs the pelvis to be the root joint")
    root_translation = parts["joint_pos"][:, pelvis].clone()
    root_translation[:, 0] += parts["root_pos"][:, 0]
    root_translation[:, 2] += parts["root_pos"][:, 2]
    G = sixd_to_quat(parts["joint_rot"])
    contacts = parts["contacts"].clamp(0, 1)
    return Motion.from_global(skeleton, fps, root_translation, G, contacts)


# ---------------------------------------------------------------------------- local root (Sec. 4.2)
def global_to_local_root(root: torch.Tensor, fps: float) -> torch.Tensor:
    """``(..., T, 5)`` [x, y, z, cos, sin] -> ``(..., T, 4)`` [heading rate rad/s, lateral and forward
    planar velocity m/s in the heading frame, height m]. Differentiable; forward differences with the
    last frame repeating the previous one."""
    pos, hd = root[..., :3], root[..., 3:5]
    hd = hd / hd.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    c, s = hd[..., 0], hd[..., 1]
    # relative rotation between consecutive headings: (cos d, sin d)
    cd = c[..., :-1] * c[..., 1:] + s[..., :-1] * s[..., 1:]
    sd = c[..., :-1] * s[..., 1:] - s[..., :-1] * c[..., 1:]
    dpsi = torch.atan2(sd, cd) * fps
    dxz = (pos[..., 1:, :] - pos[..., :-1, :])[..., [0, 2]] * fps
    vx, vz = dxz[..., 0], dxz[..., 1]
    c0, s0 = c[..., :-1], s[..., :-1]  # psi measured from +Z: forward = (sin, cos), lateral = (cos, -sin)
    lateral = vx * c0 - vz * s0
    forward = vx * s0 + vz * c0
    local = torch.stack([dpsi, lateral, forward], dim=-1)
    if local.shape[-2] == 0:
        local = torch.zeros(*pos.shape[:-1], 3, dtype=pos.dtype, device=pos.device)
    else:
        local = torch.cat([local, local[..., -1:, :]], dim=-2)
    return torch.cat([local, pos[..., 1:2]], dim=-1)


def local_to_global_root(local: torch.Tensor, fps: float, start: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`global_to_local_root`: integrate from ``start (..., 5)`` (first frame's global
    root: x, y, z, cos, sin); returns ``(..., T, 5)``."""
    psi0 = torch.atan2(start[..., 4], start[..., 3])
    dpsi = local[..., 0] / fps
    psi = psi0[..., None] + torch.cumsum(dpsi, dim=-1) - dpsi  # exclusive cumsum
    c, s = torch.cos(psi), torch.sin(psi)
    lat, fwd = local[..., 1] / fps, local[..., 2] / fps
    vx = lat * c + fwd * s
    vz = -lat * s + fwd * c
    x = start[..., 0:1] + torch.cumsum(vx, dim=-1) - vx
    z = start[..., 2:3] + torch.cumsum(vz, dim=-1) - vz
    return torch.stack([x, local[..., 3], z, c, s], dim=-1)
