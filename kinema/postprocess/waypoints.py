"""Smoothed-root waypoints in post-processing: a smooth root x/z displacement whose smoothed pelvis
passes through the waypoints.

A waypoint targets the *smoothed* root, the pelvis x/z under a Gaussian of ``root_sigma`` seconds
(kinema.motion.smoothing). The displacement ``d (T, 2)`` of the root x/z therefore acts on the
targets through the smoothing matrix ``S``: ``S d = residual`` at the waypoint frames.

For a few isolated waypoints that system is easy. For a *dense* path (a target on every frame) it
asks to invert the Gaussian, which is ill-conditioned: components of ``d`` with a period near two
Gaussian widths pass through ``S`` attenuated a hundredfold, so hitting the smoothed targets exactly
bought centimetres with metres of oscillation (measured on examples/constraints/dense_path.json: the
pelvis at 443 m/s, joints moved 22 m). The displacement is therefore a regularised least-squares fit,

    minimise  |D2 d|^2 + |D1 d|^2 / ell^2 + |d|^2 / ell^4 + WAYPOINT_WEIGHT * sum_k |S_k d - residual_k|^2

(``D1``, ``D2`` the first and second differences, ``ell`` the blend radius in frames; without the
first-difference term a displacement could ramp up linearly, at no cost, towards the end of the motion
next to a late waypoint: 3.6 m/s added to the pelvis), with ``d = 0`` on pinned frames
(full-body keyframes) as hard constraints. Measured on the shipped model, 5-s walks, seeds 0-1: the
dense path is followed within 0.6 cm on average (2.2 cm at worst, raw 3.6-4.7 cm) with the pelvis no
faster than raw (1.5 vs 1.7 m/s); isolated waypoints (examples/constraints/waypoints.json) are still
hit within 0.005 cm. A weight of 10 lowered the dense-path error only from 0.63 to 0.52 cm but
raised the pelvis to 2.6 m/s; exact hard constraints on a thinned subset (one per Gaussian width)
still oscillated (4 m/s).
"""

from __future__ import annotations

import math

import torch

from kinema.kinematics import forward_kinematics
from kinema.motion.smoothing import smooth_time
from kinema.postprocess.ik import raised_cosine

#: weight (1/m^2, against a curvature term in m/frame^2) of each smoothed-root waypoint residual
WAYPOINT_WEIGHT = 1.0


def smoothing_matrix(num_frames: int, sigma_frames: float) -> torch.Tensor:
    """``(T, T)`` float64 matrix S with ``S @ x == smooth_time(x, sigma_frames)`` (the op is linear)."""
    return smooth_time(torch.eye(num_frames, dtype=torch.float64), sigma_frames)


def frame_envelope(frames: torch.Tensor, num_frames: int, radius: float) -> torch.Tensor:
    """``(T,)`` raised cosine of the distance (frames) to the nearest of ``frames``, 0 beyond ``radius``."""
    if frames.numel() == 0:
        return torch.zeros(num_frames, dtype=torch.float64)
    t = torch.arange(num_frames, dtype=torch.float64)
    d = (t[:, None] - frames.to(torch.float64)[None]).abs().min(dim=1).values
    return raised_cosine(d / max(radius, 1e-6))


def _difference(T: int, idx: torch.Tensor, order: int) -> torch.Tensor:
    """``(T - order, n)`` first- or second-difference operator restricted to the columns ``idx``."""
    D = torch.zeros(max(T - order, 0), T, dtype=torch.float64)
    if T > order:
        i = torch.arange(T - order)
        for k, c in enumerate((-1.0, 1.0) if order == 1 else (1.0, -2.0, 1.0)):
            D[i, i + k] = c
    return D[:, idx]


def root_waypoints(skel, L, r, targets, fps: float, radius: float, pinned: torch.Tensor) -> torch.Tensor:
    """Root translation ``(T, 3)`` whose smoothed pelvis x/z follows ``targets.root_xz`` (see module doc).

    ``L (T, J, 4)`` local rotations, ``r (T, 3)`` root translation (metres, float64), ``pinned (T,)``
    frames that must not move. The displacement is zero outside the frames that can influence a waypoint
    (Gaussian reach + blend radius)."""
    T = r.shape[0]
    sigma = targets.root_sigma * fps
    S = smoothing_matrix(T, sigma)
    pelvis = skel.roles.get("pelvis", 0)
    _, P = forward_kinematics(L, r, skel.offsets, skel.parents)
    f, xz = targets.root_xz
    last = {int(k): i for i, k in enumerate(f.tolist())}  # repeated frames: the last one wins
    f, xz = torch.tensor(list(last)), xz[torch.tensor(list(last.values()))]
    resid = xz - (S @ P[:, pelvis][:, [0, 2]])[f]
    idx = torch.nonzero(frame_envelope(f, T, math.ceil(3 * sigma) + radius + 1) > 0).flatten()
    n = idx.numel()
    D1, D2 = _difference(T, idx, 1), _difference(T, idx, 2)
    ell = max(radius, 1.0)  # correlation length (frames) of the displacement
    Sf = S[f][:, idx]
    Q = D2.T @ D2 + D1.T @ D1 / ell**2 + torch.eye(n, dtype=torch.float64) / ell**4 + WAYPOINT_WEIGHT * Sf.T @ Sf
    g = WAYPOINT_WEIGHT * Sf.T @ resid
    pin = torch.nonzero(pinned[idx]).flatten()
    d = torch.linalg.solve(Q, g)
    if pin.numel():  # equality d[pin] = 0 through the KKT system of the same objective
        A = torch.eye(n, dtype=torch.float64)[pin]
        X = torch.linalg.solve(Q, A.T)
        d = d - X @ torch.linalg.solve(A @ X, A @ d)
    r = r.clone()
    r[idx, 0] += d[:, 0]
    r[idx, 2] += d[:, 1]
    return r
