"""Rotation representations and conversions in torch (see docs/conventions.md).

Every function is batched over arbitrary leading axes, differentiable, keeps the input dtype and
device, and is written so that neither values nor gradients become NaN at the usual singular
points (zero angle, 180 degrees, Euler gimbal lock).  Where a formula has a removable singularity
we evaluate a Taylor series on the small side and feed the exact branch a harmless dummy input
("double where"), because ``torch.where`` still back-propagates through the unused branch.

Conventions: quaternions are ``(w, x, y, z)``; matrices act on column vectors; axis-angle is
``unit_axis * angle``; 6D is the first two matrix columns ``(r00, r10, r20, r01, r11, r21)``.
"""

from __future__ import annotations

import torch

from kinema.errors import KinemaError

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
_SMALL_ANGLE_SQ = 1e-4  # below this squared angle the Taylor series are exact to float64 precision


class _EulerOrderError(KinemaError, ValueError):
    """Bad Euler order string (a ValueError, and a KinemaError so the CLI reports it cleanly)."""


def _tiny(x: torch.Tensor) -> float:
    return torch.finfo(x.dtype).tiny


def _eps(x: torch.Tensor) -> float:
    return torch.finfo(x.dtype).eps


def _safe_normalize(x: torch.Tensor) -> torch.Tensor:
    """Unit vectors along the last axis; a zero vector stays zero with a finite gradient."""
    return x * torch.rsqrt((x * x).sum(-1, keepdim=True).clamp_min(_tiny(x)))


def _check_order(order: str) -> tuple[int, int, int]:
    """Axis indices (i, j, k) of a validated Tait-Bryan order string such as "ZXY"."""
    if not isinstance(order, str) or order not in EULER_ORDERS:
        raise _EulerOrderError(
            f"invalid Euler order {order!r}: expected one of {', '.join(EULER_ORDERS)} "
            "(uppercase, intrinsic, BVH channel order)"
        )
    return tuple("XYZ".index(c) for c in order)  # type: ignore[return-value]


# ----------------------------------------------------------------------------- quaternion basics


def quat_normalize(q: torch.Tensor) -> torch.Tensor:
    """Scale quaternions ``(..., 4)`` to unit norm (a zero quaternion stays zero, no NaN)."""
    return _safe_normalize(q)


def quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a * b`` (broadcast); as a rotation it applies ``b`` first, then ``a``."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        dim=-1,
    )


def quat_conjugate(q: torch.Tensor) -> torch.Tensor:
    """``(w, -x, -y, -z)``: the inverse rotation for unit quaternions."""
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def quat_inverse(q: torch.Tensor) -> torch.Tensor:
    """Multiplicative inverse ``conj(q) / |q|^2`` (also correct for non-unit quaternions)."""
    return quat_conjugate(q) / (q * q).sum(-1, keepdim=True).clamp_min(_tiny(q))


def quat_rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)`` (shapes broadcast)."""
    w, u = q[..., :1], q[..., 1:]
    u, v = torch.broadcast_tensors(u, v)
    t = 2.0 * torch.linalg.cross(u, v, dim=-1)
    return v + w * t + torch.linalg.cross(u, t, dim=-1)


def quat_identity(shape, dtype: torch.dtype = torch.float32, device=None) -> torch.Tensor:
    """Identity quaternions of shape ``(*shape, 4)``; ``shape`` is an int or a tuple."""
    if isinstance(shape, int):
        shape = (shape,)
    q = torch.zeros((*shape, 4), dtype=dtype, device=device)
    q[..., 0] = 1.0
    return q


def quat_standardize(q: torch.Tensor) -> torch.Tensor:
    """Pick the representative with ``w >= 0`` (q and -q are the same rotation)."""
    return torch.where(q[..., :1] < 0, -q, q)


def quat_make_continuous(q: torch.Tensor, dim: int = 0) -> torch.Tensor:
    """Flip signs along the time axis ``dim`` so consecutive quaternions have dot product >= 0.

    The first sample keeps its sign; removing the q/-q jumps makes interpolation and finite
    differences along time meaningful.  ``dim`` indexes ``q``'s axes and may not be the last one.
    """
    nd = q.dim()
    d = dim + nd if dim < 0 else dim
    if not 0 <= d < nd - 1:
        raise ValueError(f"dim={dim} must name a leading (non-quaternion) axis of shape {tuple(q.shape)}")
    qm = q.movedim(d, 0)
    if qm.shape[0] < 2:
        return q.clone()
    dots = (qm[1:] * qm[:-1]).sum(-1)
    flips = torch.where(dots < 0, -1.0, 1.0).to(q.dtype)
    signs = torch.cat((torch.ones_like(flips[:1]), torch.cumprod(flips, dim=0)), dim=0)
    return (qm * signs.unsqueeze(-1)).movedim(0, d)


def quat_between(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Minimal (shortest-arc) rotation taking direction ``u (..., 3)`` to direction ``v (..., 3)``.

    Uses ``q = (1 + u.v, u x v)`` normalised, with ``1 + u.v`` rewritten as ``|u x v|^2 / (1 - u.v)``
    when the vectors point apart (no cancellation).  Near-opposite inputs make ``u x v`` tiny, so its
    rounding error along ``u`` would tilt the axis; projecting it off ``u`` keeps ``q u = v`` accurate
    to rounding.  For exactly opposite vectors the axis is undetermined; we rotate by 180 degrees about
    an axis perpendicular to ``u``.
    """
    u, v = torch.broadcast_tensors(_safe_normalize(u), _safe_normalize(v))
    d = (u * v).sum(-1, keepdim=True)
    c = torch.linalg.cross(u, v, dim=-1)
    c = c - (c * u).sum(-1, keepdim=True) * u
    c2 = (c * c).sum(-1, keepdim=True)
    apart = d < 0
    w = torch.where(apart, c2 / torch.where(apart, 1.0 - d, torch.ones_like(d)), 1.0 + d)
    q_general = _safe_normalize(torch.cat((w, c), dim=-1))
    # perpendicular axis for the 180-degree case: cross u with the basis axis least aligned with it
    basis = torch.nn.functional.one_hot(u.abs().argmin(-1), 3).to(u.dtype)
    perp = _safe_normalize(torch.linalg.cross(u, basis, dim=-1))
    q_opposite = torch.cat((torch.zeros_like(d), perp), dim=-1)
    opposite = apart & (c2 < _eps(u) ** 2)
    return torch.where(opposite, q_opposite, q_general)


# ----------------------------------------------------------------------------- matrices


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` (non-unit q is normalised)."""
    w, x, y, z = q.unbind(-1)
    s = 2.0 / (q * q).sum(-1).clamp_min(_tiny(q))
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    rows = (
        1.0 - yy - zz, xy - wz, xz + wy,
        xy + wz, 1.0 - xx - zz, yz - wx,
        xz - wy, yz + wx, 1.0 - xx - yy,
    )  # fmt: skip
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def matrix_to_quat(m: torch.Tensor) -> torch.Tensor:
    """Unit quaternions ``(..., 4)`` with ``w >= 0`` from rotation matrices ``(..., 3, 3)``.

    Shepperd's method without branches: compute the four candidate quaternions, each obtained by
    dividing by one of ``4w^2, 4x^2, 4y^2, 4z^2``, and keep the one with the largest divisor
    (always >= 1, so well conditioned).  Divisors are clamped so the unused candidates stay finite.
    """
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m.flatten(-2).unbind(-1)
    sq = torch.stack(
        (
            1.0 + m00 + m11 + m22,
            1.0 + m00 - m11 - m22,
            1.0 - m00 + m11 - m22,
            1.0 - m00 - m11 + m22,
        ),
        dim=-1,
    )  # 4w^2, 4x^2, 4y^2, 4z^2
    cand = torch.stack(
        (
            torch.stack((sq[..., 0], m21 - m12, m02 - m20, m10 - m01), dim=-1),
            torch.stack((m21 - m12, sq[..., 1], m10 + m01, m02 + m20), dim=-1),
            torch.stack((m02 - m20, m10 + m01, sq[..., 2], m21 + m12), dim=-1),
            torch.stack((m10 - m01, m02 + m20, m21 + m12, sq[..., 3]), dim=-1),
        ),
        dim=-2,
    )  # row r = 4 * q_r * q
    cand = cand / (2.0 * torch.sqrt(sq.clamp_min(0.1))).unsqueeze(-1)
    best = sq.argmax(-1, keepdim=True).unsqueeze(-1).expand(*sq.shape[:-1], 1, 4)
    q = torch.gather(cand, -2, best).squeeze(-2)
    return quat_standardize(_safe_normalize(q))


# ----------------------------------------------------------------------------- axis-angle


def _angle_and_small(sq_angle: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(angle, small mask, squared angle) with the angle computed on a safe dummy where small."""
    small = sq_angle < _SMALL_ANGLE_SQ
    angle = torch.sqrt(torch.where(small, torch.ones_like(sq_angle), sq_angle))
    return angle, small, sq_angle


def axis_angle_to_quat(aa: torch.Tensor) -> torch.Tensor:
    """Quaternions ``(..., 4)`` from axis-angle vectors ``(..., 3)``."""
    angle, small, t2 = _angle_and_small((aa * aa).sum(-1, keepdim=True))
    half = 0.5 * angle
    w = torch.where(small, 1.0 - t2 / 8.0 + t2 * t2 / 384.0, torch.cos(half))
    k = torch.where(small, 0.5 - t2 / 48.0 + t2 * t2 / 3840.0, torch.sin(half) / angle)
    return torch.cat((w, k * aa), dim=-1)


def quat_to_axis_angle(q: torch.Tensor) -> torch.Tensor:
    """Axis-angle vectors ``(..., 3)`` with angle in ``[0, pi]`` from quaternions ``(..., 4)``."""
    q = quat_standardize(_safe_normalize(q))
    w, xyz = q[..., :1], q[..., 1:]
    s2 = (xyz * xyz).sum(-1, keepdim=True)
    s, small, _ = _angle_and_small(s2)
    # angle / s = 2 atan2(s, w) / s; for small s (so w ~ 1) use its series in s^2
    wc = w.clamp_min(0.5)
    series = 2.0 / wc - 2.0 * s2 / (3.0 * wc**3) + 2.0 * s2 * s2 / (5.0 * wc**5)
    k = torch.where(small, series, 2.0 * torch.atan2(s, w) / s)
    return k * xyz


def axis_angle_to_matrix(aa: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``(..., 3, 3)`` from axis-angle ``(..., 3)`` via Rodrigues' formula."""
    angle, small, t2 = _angle_and_small((aa * aa).sum(-1, keepdim=True))
    half_sin = torch.sin(0.5 * angle)
    a = torch.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, torch.sin(angle) / angle)
    b = torch.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, 2.0 * (half_sin / angle) ** 2)
    x, y, z = aa.unbind(-1)
    zero = torch.zeros_like(x)
    k = torch.stack((zero, -z, y, z, zero, -x, -y, x, zero), dim=-1).unflatten(-1, (3, 3))
    eye = torch.eye(3, dtype=aa.dtype, device=aa.device)
    return eye + a.unsqueeze(-1) * k + b.unsqueeze(-1) * (k @ k)


def matrix_to_axis_angle(m: torch.Tensor) -> torch.Tensor:
    """Axis-angle ``(..., 3)`` (angle in ``[0, pi]``) from rotation matrices ``(..., 3, 3)``."""
    return quat_to_axis_angle(matrix_to_quat(m))


# ----------------------------------------------------------------------------- 6D


def matrix_to_sixd(m: torch.Tensor) -> torch.Tensor:
    """6D representation ``(..., 6)``: first two columns ``(r00, r10, r20, r01, r11, r21)``."""
    return torch.cat((m[..., :, 0], m[..., :, 1]), dim=-1)


def sixd_to_matrix(d: torch.Tensor) -> torch.Tensor:
    """Rotation matrices from (possibly unnormalised) 6D vectors by Gram-Schmidt (Zhou et al.)."""
    b1 = _safe_normalize(d[..., :3])
    a2 = d[..., 3:]
    b2 = _safe_normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack((b1, b2, b3), dim=-1)


def quat_to_sixd(q: torch.Tensor) -> torch.Tensor:
    """6D representation ``(..., 6)`` of quaternions ``(..., 4)``."""
    return matrix_to_sixd(quat_to_matrix(q))


def sixd_to_quat(d: torch.Tensor) -> torch.Tensor:
    """Quaternions ``(..., 4)`` (w >= 0) from 6D vectors ``(..., 6)``."""
    return matrix_to_quat(sixd_to_matrix(d))


# ----------------------------------------------------------------------------- Euler angles


def _elementary_matrix(angle: torch.Tensor, axis: int) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    one, zero = torch.ones_like(angle), torch.zeros_like(angle)
    if axis == 0:
        rows = (one, zero, zero, zero, c, -s, zero, s, c)
    elif axis == 1:
        rows = (c, zero, s, zero, one, zero, -s, zero, c)
    else:
        rows = (c, -s, zero, s, c, zero, zero, zero, one)
    return torch.stack(rows, dim=-1).unflatten(-1, (3, 3))


def euler_to_matrix(angles: torch.Tensor, order: str) -> torch.Tensor:
    """``R = R_{order[0]}(a0) @ R_{order[1]}(a1) @ R_{order[2]}(a2)`` (intrinsic, BVH channel order)."""
    axes = _check_order(order)
    mats = [_elementary_matrix(angles[..., n], axes[n]) for n in range(3)]
    return mats[0] @ mats[1] @ mats[2]


def euler_to_quat(angles: torch.Tensor, order: str) -> torch.Tensor:
    """Quaternions (w >= 0) for Euler angles with the same convention as ``euler_to_matrix``."""
    axes = _check_order(order)
    q = None
    for n in range(3):
        half = 0.5 * angles[..., n]
        parts = [torch.zeros_like(half)] * 4
        parts[0], parts[1 + axes[n]] = torch.cos(half), torch.sin(half)
        qn = torch.stack(parts, dim=-1)
        q = qn if q is None else quat_mul(q, qn)
    return quat_standardize(q)


def matrix_to_euler(m: torch.Tensor, order: str) -> torch.Tensor:
    """Euler angles ``(..., 3)`` such that ``euler_to_matrix(angles, order) == m``.

    The middle angle lies in ``[-pi/2, pi/2]``, the others in ``(-pi, pi]``.  The first angle ``a``
    is read from the matrix, then ``b`` and ``c`` are solved from ``M = R_i(a)^T m = R_j(b) R_k(c)``
    using only unit-length atan2 arguments, so the reconstruction stays exact even when ``a`` is
    ill-conditioned near gimbal lock.  At gimbal lock (middle angle +-90 degrees) only ``a + -c`` is
    determined; we then choose ``c = 0`` (like scipy).
    """
    i, j, k = _check_order(order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # +1 for cyclic orders XYZ, YZX, ZXY
    r = lambda a, b: m[..., a, b]  # noqa: E731
    y_gen, x_gen = -s * r(j, k), r(k, k)  # cos(b) * (sin a, cos a)
    lock = (y_gen * y_gen + x_gen * x_gen) < (10.0 * _eps(m)) ** 2
    y_lock, x_lock = s * r(k, j), r(j, j)  # column j = R_i(a) e_j when c = 0
    a = torch.atan2(torch.where(lock, y_lock, y_gen), torch.where(lock, x_lock, x_gen))
    ca, sa = torch.cos(a), torch.sin(a)
    m_ji = ca * r(j, i) + s * sa * r(k, i)
    m_jj = ca * r(j, j) + s * sa * r(k, j)
    m_kk = -s * sa * r(j, k) + ca * r(k, k)
    b = torch.atan2(s * r(i, k), m_kk)
    c = torch.atan2(s * m_ji, m_jj)
    return torch.stack((a, b, c), dim=-1)


def quat_to_euler(q: torch.Tensor, order: str) -> torch.Tensor:
    """Euler angles ``(..., 3)`` of quaternions, same convention as ``matrix_to_euler``."""
    return matrix_to_euler(quat_to_matrix(q), order)


def quat_angle_deg(q: torch.Tensor, q_target: torch.Tensor) -> torch.Tensor:
    """Geodesic angle in degrees between quaternions ``(..., 4)`` (normalised first; q and -q are the
    same rotation): ``2 atan2(|v|, |w|)`` for ``(w, v) = conj(q_target) q``, in [0, 180] (accurate for
    nearly equal inputs, unlike ``acos``)."""
    rel = quat_mul(quat_conjugate(quat_normalize(q_target)), quat_normalize(q))
    return torch.rad2deg(2.0 * torch.atan2(rel[..., 1:].norm(dim=-1), rel[..., 0].abs()))


# ----------------------------------------------------------------------------- interpolation, mirror


def quat_slerp(q0: torch.Tensor, q1: torch.Tensor, t) -> torch.Tensor:
    """Spherical linear interpolation along the shortest path (``t=0`` gives q0, ``t=1`` gives q1).

    ``t`` is a float or a tensor broadcastable to the leading shape ``(...,)``.  The half-angle is
    ``2 atan2(|q1 - q0|, |q1 + q0|)`` (accurate for nearly equal inputs, unlike ``acos``), and a
    Taylor expansion of the weights is used when it is tiny.
    """
    q0, q1 = _safe_normalize(q0), _safe_normalize(q1)
    q1 = torch.where((q0 * q1).sum(-1, keepdim=True) < 0, -q1, q1)
    t = torch.as_tensor(t, dtype=q0.dtype, device=q0.device).unsqueeze(-1)
    diff, summ = q1 - q0, q1 + q0
    n_diff = torch.sqrt((diff * diff).sum(-1, keepdim=True).clamp_min(_tiny(q0)))
    n_sum = torch.sqrt((summ * summ).sum(-1, keepdim=True).clamp_min(_tiny(q0)))
    omega = 2.0 * torch.atan2(n_diff, n_sum)
    small = omega < 1e-3
    om = torch.where(small, torch.ones_like(omega), omega)
    o2 = omega * omega
    w0 = torch.where(
        small,
        (1.0 - t) * (1.0 + (1.0 - (1.0 - t) ** 2) * o2 / 6.0),
        torch.sin((1.0 - t) * om) / torch.sin(om),
    )
    w1 = torch.where(small, t * (1.0 + (1.0 - t * t) * o2 / 6.0), torch.sin(t * om) / torch.sin(om))
    return _safe_normalize(w0 * q0 + w1 * q1)


def mirror_quat_x(q: torch.Tensor) -> torch.Tensor:
    """Mirror a rotation through the plane x = 0: returns ``(w, x, -y, -z)``.

    With ``S = diag(-1, 1, 1)`` the mirrored rotation is ``S R S``: reflecting the pose of a
    left/right-symmetric character turns a rotation about axis ``n`` by ``theta`` into a rotation
    about ``(n_x, -n_y, -n_z)`` by ``theta``.  (Swapping left and right joints is the caller's job.)
    """
    return q * q.new_tensor([1.0, 1.0, -1.0, -1.0])
