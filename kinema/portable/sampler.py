"""The sampling loop of docs/onnx_runtime.md in numpy: what one DDIM step does around the denoiser graph.

Everything here acts on one motion ``(T, D)`` in normalised feature units unless said otherwise; the
torch sampler (kinema.human.sampling) is the implementation this reference must agree with, and the
JavaScript runtime (web/kinema-runtime.js) follows the same steps.
"""

from __future__ import annotations

import math

import numpy as np


def spaced_timesteps(num_train_steps: int, steps: int) -> list[int]:
    """The "trailing" DDIM steps: ``floor((2 (n - i) T + n) / (2 n)) - 1`` for ``i = 0 .. n-1``."""
    T, n = num_train_steps, steps
    return [(2 * (n - i) * T + n) // (2 * n) - 1 for i in range(n)]


def gaussian_kernel(sigma_frames: float) -> np.ndarray:
    """Normalised Gaussian taps over +-ceil(3 sigma) frames (one tap of 1 for sigma <= 0)."""
    radius = max(int(math.ceil(3.0 * sigma_frames)), 0)
    if sigma_frames <= 0 or radius == 0:
        return np.ones(1)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma_frames) ** 2)
    return k / k.sum()


def smooth_time(x: np.ndarray, sigma_frames: float) -> np.ndarray:
    """``x (T, C)`` Gaussian-smoothed along T, ends padded by point reflection ``2 x[0] - x[k]``."""
    kernel = gaussian_kernel(sigma_frames).astype(np.float32)
    r = len(kernel) // 2
    if r == 0:
        return x.copy()
    T = x.shape[0]
    left = 2 * x[:1] - x[np.minimum(np.arange(r, 0, -1), T - 1)]
    right = 2 * x[-1:] - x[np.maximum(np.arange(T - 2, T - 2 - r, -1), 0)]
    pad = np.concatenate([left, x, right])
    return sum(kernel[k] * pad[k : k + T] for k in range(len(kernel))).astype(x.dtype)


def pelvis_offset_targets(x0: np.ndarray, tgt: np.ndarray, mask: np.ndarray, mean: np.ndarray, std: np.ndarray,
                          root_xz: list[int], pelvis_xz: list[int], sigma_frames: float) -> np.ndarray:
    """Root x/z targets that put the smoothed pelvis on a root target: on frames with a root x/z target
    and no pelvis x/z target, ``tgt.root_xz -= smooth(pelvis offset in metres) / std``."""
    bias = smooth_time(x0[:, pelvis_xz] * std[pelvis_xz] + mean[pelvis_xz], sigma_frames)
    free = (mask[:, root_xz] > 0) & (mask[:, pelvis_xz] == 0)
    out = tgt.copy()
    out[:, root_xz] = np.where(free, tgt[:, root_xz] - bias / std[root_xz], tgt[:, root_xz])
    return out


def displace_root(x0: np.ndarray, aim: np.ndarray | None, mask: np.ndarray | None, origin: np.ndarray,
                  root_xz: list[int]) -> np.ndarray:
    """Move the root x/z onto its targets by a displacement interpolated linearly between constrained
    frames (held after the last); a free frame 0 takes its channel's first target's displacement, or
    goes to ``origin`` when the channel has no target (``anchor_start``)."""
    x = x0[:, root_xz]
    T = x.shape[0]
    if mask is None or aim is None:
        m, r = np.zeros_like(x, dtype=bool), np.zeros_like(x)
    else:
        m = mask[:, root_xz] > 0
        r = np.where(m, aim[:, root_xz] - x, 0).astype(x.dtype)
    r0 = origin - x[0]
    has = m.any(axis=0)
    first = np.where(m, np.arange(T)[:, None], T).min(axis=0).clip(max=T - 1)
    r0 = np.where(has, r[first, [0, 1]], r0)
    r[0] = np.where(m[0], r[0], r0)
    m[0] = True
    t = np.broadcast_to(np.arange(T)[:, None], x.shape)
    prev = np.maximum.accumulate(np.where(m, t, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(m, t, T)[::-1], axis=0)[::-1]
    span = np.maximum(nxt - prev, 1).astype(x.dtype)
    w = np.where(nxt < T, (t - prev).astype(x.dtype) / span, 0).astype(x.dtype)
    cols = np.array([0, 1])[None, :]
    out = x0.copy()
    out[:, root_xz] = x + (1 - w) * r[prev, cols] + w * r[np.minimum(nxt, T - 1), cols]
    return out


def ddim_step(x0: np.ndarray, x_t: np.ndarray, abar_t: float, abar_prev: float | None) -> np.ndarray:
    """Deterministic DDIM (eta 0) from step t to the previous one (None: the end, returns x0)."""
    if abar_prev is None:
        return x0
    eps = (x_t - np.float32(math.sqrt(abar_t)) * x0) / np.float32(math.sqrt(1.0 - abar_t))
    return np.float32(math.sqrt(abar_prev)) * x0 + np.float32(math.sqrt(1.0 - abar_prev)) * eps


def sixd_to_matrix(d: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` (columns b1, b2, b3) of 6D vectors by Gram-Schmidt."""
    def unit(v):
        return v / np.sqrt(np.maximum((v * v).sum(-1, keepdims=True), np.finfo(v.dtype).tiny))

    b1 = unit(d[..., :3])
    a2 = d[..., 3:]
    b2 = unit(a2 - (b1 * a2).sum(-1, keepdims=True) * b1)
    return np.stack([b1, b2, np.cross(b1, b2)], axis=-1)


def joint_positions(features: np.ndarray, layout: dict, skeleton: dict) -> np.ndarray:
    """World joint positions ``(T, J, 3)`` of unnormalised features ``(T, D)``: the root joint at its
    ``joint_pos`` plus the smoothed root x/z, every other joint at its parent plus the parent's global
    rotation (6D ``joint_rot``) applied to its offset."""
    J = len(skeleton["parents"])
    jp = features[:, slice(*layout["slices"]["joint_pos"])].reshape(-1, J, 3)
    rot = sixd_to_matrix(features[:, slice(*layout["slices"]["joint_rot"])].reshape(-1, J, 6).astype(np.float64))
    rx, rz = layout["root_xz"]
    root = skeleton["root"]
    offsets = np.asarray(skeleton["offsets"], dtype=np.float64)
    pos = np.zeros((features.shape[0], J, 3))
    pos[:, root] = jp[:, root] + np.stack([features[:, rx], np.zeros(len(features)), features[:, rz]], axis=-1)
    for j, p in enumerate(skeleton["parents"]):
        if p >= 0:
            pos[:, j] = pos[:, p] + rot[:, p] @ offsets[j]
    return pos


def axis_angle_to_matrix(aa: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of axis-angle vectors ``(..., 3)`` (Rodrigues)."""
    angle = np.linalg.norm(aa, axis=-1, keepdims=True)
    axis = aa / np.maximum(angle, 1e-12)
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle[..., 0]), np.sin(angle[..., 0])
    C = 1 - c
    return np.stack([np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], -1),
                     np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], -1),
                     np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], -1)], -2)


def pose_from_local(local_aa: np.ndarray, root: np.ndarray, skeleton: dict) -> tuple[np.ndarray, np.ndarray]:
    """Global rotation matrices ``(J, 3, 3)`` and positions ``(J, 3)`` of one pose given as local axis-angle
    rotations ``(J, 3)`` and the root joint's position: ``G_j = G_parent L_j``, ``p_j = p_parent + G_parent
    offset_j`` (parents before children)."""
    L = axis_angle_to_matrix(np.asarray(local_aa, dtype=np.float64))
    offsets = np.asarray(skeleton["offsets"], dtype=np.float64)
    G, P = np.zeros_like(L), np.zeros((len(L), 3))
    for j, p in enumerate(skeleton["parents"]):
        if p < 0:
            G[j], P[j] = L[j], root
        else:
            G[j], P[j] = G[p] @ L[j], P[p] + G[p] @ offsets[j]
    return G, P


def heading_of(P: np.ndarray, left_hip: int, right_hip: int) -> np.ndarray:
    """``(cos psi, sin psi)`` of a pose's positions ``(J, 3)``: up x (right hip - left hip) on the ground."""
    v = P[right_hip] - P[left_hip]
    fx, fz = v[2], -v[0]
    n = max(math.hypot(fx, fz), 1e-9)
    return np.array([fz / n, fx / n])
