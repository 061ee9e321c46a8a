"""Tests for kinema.geometry.rotations: scipy agreement, round trips, singular inputs, gradients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation, Slerp

from kinema.errors import KinemaError
from kinema.geometry import rotations as R

ORDERS = R.EULER_ORDERS
DTYPES = [(torch.float64, 1e-10), (torch.float32, 1e-5)]
N = 64


def _sp_quat(rot: Rotation) -> np.ndarray:
    """scipy (x, y, z, w) -> our (w, x, y, z)."""
    return np.roll(rot.as_quat(), 1, axis=-1)


def _to_sp(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.roll(np.asarray(q, dtype=np.float64), -1, axis=-1))


def _t(x, dtype) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x), dtype=dtype)


def _close(a: torch.Tensor, b, tol: float):
    b = torch.as_tensor(np.asarray(b), dtype=a.dtype)
    assert torch.isfinite(a).all()
    torch.testing.assert_close(a, b, atol=tol, rtol=0)


def _close_quat(a: torch.Tensor, b, tol: float):
    """Quaternions equal up to the q/-q ambiguity."""
    b = torch.as_tensor(np.asarray(b), dtype=a.dtype)
    sign = torch.where((a * b).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(a.dtype)
    _close(a, b * sign, tol)


@pytest.fixture
def rots() -> Rotation:
    return Rotation.random(N, random_state=1234)


# ----------------------------------------------------------------------------- scipy agreement


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_quat_matrix_vs_scipy(rots, dtype, tol):
    q = _t(_sp_quat(rots), dtype)
    _close(R.quat_to_matrix(q), rots.as_matrix(), tol)
    q_back = R.matrix_to_quat(_t(rots.as_matrix(), dtype))
    assert (q_back[..., 0] >= 0).all()
    _close_quat(q_back, _sp_quat(rots), tol)
    _close(R.matrix_to_quat(R.quat_to_matrix(q)), R.quat_standardize(q), tol)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_axis_angle_vs_scipy(rots, dtype, tol):
    rv, q, m = rots.as_rotvec(), _sp_quat(rots), rots.as_matrix()
    _close_quat(R.axis_angle_to_quat(_t(rv, dtype)), q, tol)
    _close(R.quat_to_axis_angle(_t(q, dtype)), rv, tol)
    _close(R.axis_angle_to_matrix(_t(rv, dtype)), m, tol)
    _close(R.matrix_to_axis_angle(_t(m, dtype)), rv, tol)
    # angles above pi wrap to the equivalent rotation with angle in [0, pi]
    big = rv / np.linalg.norm(rv, axis=-1, keepdims=True) * 4.0
    _close(R.axis_angle_to_matrix(_t(big, dtype)), Rotation.from_rotvec(big).as_matrix(), tol)
    _close(R.quat_to_axis_angle(R.axis_angle_to_quat(_t(big, dtype))), Rotation.from_rotvec(big).as_rotvec(), tol)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_quat_algebra_vs_scipy(rots, dtype, tol):
    other = Rotation.random(N, random_state=99)
    a, b = _t(_sp_quat(rots), dtype), _t(_sp_quat(other), dtype)
    _close_quat(R.quat_mul(a, b), _sp_quat(rots * other), tol)  # scipy a*b applies b first too
    v = np.random.default_rng(0).normal(size=(N, 3))
    _close(R.quat_rotate(a, _t(v, dtype)), rots.apply(v), tol * 10)
    _close(R.quat_rotate(R.quat_conjugate(a), _t(v, dtype)), rots.inv().apply(v), tol * 10)
    _close(R.quat_mul(a, R.quat_inverse(3.0 * a)), R.quat_identity(N, dtype=dtype) / 3.0, tol)
    _close(R.quat_normalize(2.5 * a), a, tol)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_euler_vs_scipy(order, dtype, tol):
    rng = np.random.default_rng(7)
    ang = rng.uniform(-math.pi, math.pi, size=(N, 3))
    ang[:, 1] = rng.uniform(-1.5, 1.5, size=N)  # away from gimbal lock
    sp = Rotation.from_euler(order, ang)  # uppercase = intrinsic
    # our definition: R = R_{o0}(a0) R_{o1}(a1) R_{o2}(a2)
    expl = [Rotation.from_euler(order[n], ang[:, n : n + 1]).as_matrix() for n in range(3)]
    np.testing.assert_allclose(sp.as_matrix(), expl[0] @ expl[1] @ expl[2], atol=1e-12)
    m = R.euler_to_matrix(_t(ang, dtype), order)
    _close(m, sp.as_matrix(), tol)
    _close_quat(R.euler_to_quat(_t(ang, dtype), order), _sp_quat(sp), tol)
    _close(R.matrix_to_euler(_t(sp.as_matrix(), dtype), order), sp.as_euler(order), tol * 10)
    _close(R.quat_to_euler(_t(_sp_quat(sp), dtype), order), ang, tol * 10)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_slerp_vs_scipy(dtype, tol):
    key = Rotation.random(2, random_state=3)
    ts = np.linspace(0.0, 1.0, 11)
    ref = _sp_quat(Slerp([0.0, 1.0], key)(ts))
    q0, q1 = _t(_sp_quat(key[0]), dtype), _t(_sp_quat(key[1]), dtype)
    out = R.quat_slerp(q0.expand(11, 4), -q1.expand(11, 4), _t(ts, dtype))  # sign must not matter
    _close_quat(out, ref, tol)
    for t in (0.0, 0.3, 1.0):  # python float t
        _close_quat(R.quat_slerp(q0, q1, t), _sp_quat(Slerp([0.0, 1.0], key)(t)), tol)


# ----------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_euler_round_trip_any_angles(order, dtype, tol):
    ang = torch.rand(N, 3, generator=torch.Generator().manual_seed(5), dtype=dtype) * 12 - 6
    m = R.euler_to_matrix(ang, order)
    back = R.matrix_to_euler(m, order)
    assert (back[:, 1].abs() <= math.pi / 2 + tol).all()
    _close(R.euler_to_matrix(back, order), m, tol)
    _close(R.quat_to_matrix(R.euler_to_quat(ang, order)), m, tol)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_sixd(rots, dtype, tol):
    m = _t(rots.as_matrix(), dtype)
    d = R.matrix_to_sixd(m)
    _close(d, np.concatenate((rots.as_matrix()[:, :, 0], rots.as_matrix()[:, :, 1]), -1), 0.0)
    _close(R.sixd_to_matrix(d), m, tol)
    _close(R.quat_to_sixd(R.sixd_to_quat(d)), d, tol)
    noisy = d * 3.0 + 0.1 * torch.randn(d.shape, generator=torch.Generator().manual_seed(0), dtype=dtype)
    mn = R.sixd_to_matrix(noisy)
    eye = torch.eye(3, dtype=dtype).expand_as(mn)
    _close(mn.transpose(-1, -2) @ mn, eye, tol)
    _close(torch.linalg.det(mn), np.ones(N), tol)
    _close(mn[..., :, 0], R.quat_normalize(noisy[..., :3]), tol)  # first column keeps direction


# ----------------------------------------------------------------------------- shapes & dtypes


def test_batched_shapes_and_dtype():
    shape = (2, 3, 4)
    for dtype in (torch.float32, torch.float64):
        q = R.quat_normalize(torch.randn(*shape, 4, dtype=dtype))
        m = R.quat_to_matrix(q)
        checks = {
            "m": (m, (*shape, 3, 3)),
            "q": (R.matrix_to_quat(m), (*shape, 4)),
            "aa": (R.quat_to_axis_angle(q), (*shape, 3)),
            "aam": (R.axis_angle_to_matrix(R.matrix_to_axis_angle(m)), (*shape, 3, 3)),
            "6d": (R.quat_to_sixd(q), (*shape, 6)),
            "e": (R.quat_to_euler(q, "ZXY"), (*shape, 3)),
            "rot": (R.quat_rotate(q, torch.ones(3, dtype=dtype)), (*shape, 3)),
            "slerp": (R.quat_slerp(q, R.quat_identity(shape, dtype=dtype), torch.rand(2, 1, 4).to(dtype)),
                      (*shape, 4)),
            "between": (R.quat_between(torch.randn(*shape, 3, dtype=dtype), torch.ones(3, dtype=dtype)),
                        (*shape, 4)),
        }  # fmt: skip
        for name, (out, want) in checks.items():
            assert out.shape == want, name
            assert out.dtype == dtype, name
            assert torch.isfinite(out).all(), name
    assert R.quat_identity((), dtype=torch.float64).tolist() == [1.0, 0.0, 0.0, 0.0]


# ----------------------------------------------------------------------------- singular inputs


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_zero_and_tiny_angles(dtype, tol):
    aa = torch.tensor([[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [0.0, 3e-4, -2e-4], [0.02, 0.0, 0.0]], dtype=dtype)
    ref = Rotation.from_rotvec(aa.double().numpy())
    _close(R.axis_angle_to_matrix(aa), ref.as_matrix(), tol)
    _close_quat(R.axis_angle_to_quat(aa), _sp_quat(ref), tol)
    _close(R.quat_to_axis_angle(R.axis_angle_to_quat(aa)), aa, tol * 1e-2)
    _close(R.matrix_to_axis_angle(R.axis_angle_to_matrix(aa)), aa, tol)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_half_turn_rotations(dtype, tol):
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, -2, 3], [0, -1, 1]], dtype=np.float64)
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    ref = Rotation.from_rotvec(axes * math.pi)
    m = _t(ref.as_matrix(), dtype)
    q = R.matrix_to_quat(m)
    assert (q[..., 0] >= 0).all()
    _close_quat(q, _sp_quat(ref), tol)
    aa = R.matrix_to_axis_angle(m)
    _close(torch.linalg.vector_norm(aa, dim=-1), np.full(len(axes), math.pi), tol * 10)
    _close(R.axis_angle_to_matrix(aa), m, tol)
    _close(R.quat_to_matrix(R.axis_angle_to_quat(_t(axes * math.pi, dtype))), m, tol)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_gimbal_lock(order, dtype, tol):
    rng = np.random.default_rng(11)
    ang = rng.uniform(-3, 3, size=(8, 3))
    ang[:4, 1], ang[4:, 1] = math.pi / 2, -math.pi / 2
    ang_t = _t(ang, dtype).requires_grad_(True)
    m = R.euler_to_matrix(ang_t, order)
    out = R.matrix_to_euler(m, order)
    assert torch.isfinite(out).all()
    _close(R.euler_to_matrix(out, order), m.detach(), tol)
    _close(out[:, 1].abs(), np.full(8, math.pi / 2), 1e-3 if dtype == torch.float32 else 1e-7)
    (grad,) = torch.autograd.grad(out.sum() + R.quat_to_euler(R.euler_to_quat(ang_t, order), order).sum(), ang_t)
    assert torch.isfinite(grad).all()


def test_quat_between():
    rng = np.random.default_rng(2)
    u, v = rng.normal(size=(N, 3)), rng.normal(size=(N, 3)) * 5
    for dtype, tol in DTYPES:
        q = R.quat_between(_t(u, dtype), _t(v, dtype))
        un, vn = u / np.linalg.norm(u, axis=-1, keepdims=True), v / np.linalg.norm(v, axis=-1, keepdims=True)
        _close(R.quat_rotate(q, _t(un, dtype)), vn, tol)
        # minimal: rotation angle equals the angle between the vectors, axis orthogonal to both
        ang = 2 * torch.atan2(torch.linalg.vector_norm(q[..., 1:], dim=-1), q[..., 0])
        _close(ang, np.arccos(np.clip((un * vn).sum(-1), -1, 1)), tol * 100)
        _close((q[..., 1:] * _t(u, dtype)).sum(-1), np.zeros(N), tol)
        # parallel, exactly opposite and nearly opposite directions
        base = _t(un, dtype)
        _close(R.quat_between(base, 2 * base), R.quat_identity(N, dtype=dtype), tol)
        perp = R.quat_normalize(torch.linalg.cross(base, _t(vn, dtype), dim=-1))
        for eps in (0.0, 1e-12, 1e-7, 1e-4, 1e-2):  # exactly and nearly opposite
            w = R.quat_normalize(-base + eps * perp)
            qo = R.quat_between(base, w)
            assert torch.isfinite(qo).all()
            _close(R.quat_rotate(qo, base), w, tol)
    axis_cases = torch.eye(3, dtype=torch.float64)
    qa = R.quat_between(axis_cases, -axis_cases)
    _close(R.quat_rotate(qa, axis_cases), -axis_cases, 1e-12)


def test_slerp_nearly_equal_and_interior():
    q0 = R.quat_normalize(torch.randn(5, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(1)))
    for delta in (0.0, 1e-12, 1e-6):
        q1 = R.quat_normalize(q0 + delta)
        t = torch.tensor(0.25, dtype=torch.float64, requires_grad=True)
        out = R.quat_slerp(q0, q1, t)
        assert torch.isfinite(out).all()
        _close(out, q0, 1e-5)
        (g,) = torch.autograd.grad(out.sum(), t)
        assert torch.isfinite(g).all()
    # constant angular velocity: half-way point is equidistant in angle
    q1 = R.quat_normalize(torch.randn(5, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(2)))
    mid = R.quat_slerp(q0, q1, 0.5)
    d0, d1 = (mid * q0).sum(-1).abs(), (mid * q1).sum(-1).abs()
    _close(d0, d1.numpy(), 1e-10)


def test_standardize_continuous_mirror():
    q = R.quat_normalize(torch.randn(50, 3, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(4)))
    assert (R.quat_standardize(q)[..., 0] >= 0).all()
    path = R.quat_slerp(q[:1], q[1:2], torch.linspace(0, 1, 40, dtype=torch.float64)[:, None])  # (40, 3, 4)
    flips = torch.where(torch.rand(40, 3, 1, generator=torch.Generator().manual_seed(5)) < 0.5, -1.0, 1.0)
    noisy = path * flips.double()
    cont = R.quat_make_continuous(noisy, dim=0)
    assert ((cont[1:] * cont[:-1]).sum(-1) > 0).all()
    _close(R.quat_to_matrix(cont), R.quat_to_matrix(noisy).numpy(), 1e-12)
    _close(cont[0], noisy[0].numpy(), 0.0)
    moved = R.quat_make_continuous(noisy.transpose(0, 1), dim=-2)
    _close(moved, cont.transpose(0, 1).numpy(), 0.0)
    with pytest.raises(ValueError):
        R.quat_make_continuous(noisy, dim=-1)
    # mirror: S R S with S = diag(-1, 1, 1)
    s = torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64))
    _close(R.quat_to_matrix(R.mirror_quat_x(q)), (s @ R.quat_to_matrix(q) @ s).numpy(), 1e-12)


# ----------------------------------------------------------------------------- gradients & errors


def test_gradients_finite_at_singular_points():
    ident_q = R.quat_identity((2,), dtype=torch.float64)
    half_turn = torch.tensor([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.6, 0.8]], dtype=torch.float64)
    fns = {
        "aa2q": (R.axis_angle_to_quat, torch.zeros(2, 3, dtype=torch.float64)),
        "aa2m": (R.axis_angle_to_matrix, torch.zeros(2, 3, dtype=torch.float64)),
        "q2aa": (R.quat_to_axis_angle, ident_q),
        "q2aa180": (R.quat_to_axis_angle, half_turn),
        "m2aa": (R.matrix_to_axis_angle, torch.eye(3, dtype=torch.float64).expand(2, 3, 3)),
        "m2aa180": (R.matrix_to_axis_angle, R.quat_to_matrix(half_turn)),
        "m2q": (R.matrix_to_quat, torch.eye(3, dtype=torch.float64).expand(2, 3, 3)),
        "q2m": (R.quat_to_matrix, ident_q),
        "6d": (R.sixd_to_quat, R.quat_to_sixd(ident_q)),
        "e2q": (lambda a: R.euler_to_quat(a, "ZYX"), torch.zeros(2, 3, dtype=torch.float64)),
        "q2e": (lambda q: R.quat_to_euler(q, "YXZ"), ident_q),
        "slerp": (lambda q: R.quat_slerp(q, ident_q, 0.5), ident_q),
        "between": (lambda u: R.quat_between(u, torch.tensor([0.0, 0.0, 1.0], dtype=u.dtype)),
                    torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], dtype=torch.float64)),
        "norm0": (R.quat_normalize, torch.zeros(2, 4, dtype=torch.float64)),
    }  # fmt: skip
    for name, (fn, x) in fns.items():
        for dtype in (torch.float64, torch.float32):
            xi = x.detach().clone().to(dtype).requires_grad_(True)
            out = fn(xi)
            (g,) = torch.autograd.grad((out * torch.linspace(1, 2, out.shape[-1], dtype=dtype)).sum(), xi)
            assert torch.isfinite(out).all() and torch.isfinite(g).all(), (name, dtype)


def test_gradcheck_generic_points():
    gen = torch.Generator().manual_seed(8)
    aa = (torch.randn(4, 3, dtype=torch.float64, generator=gen)).requires_grad_(True)
    small = (1e-3 * torch.randn(4, 3, dtype=torch.float64, generator=gen)).requires_grad_(True)
    for x in (aa, small):
        assert torch.autograd.gradcheck(R.axis_angle_to_quat, (x,))
        assert torch.autograd.gradcheck(R.axis_angle_to_matrix, (x,))
    q = R.quat_normalize(torch.randn(4, 4, dtype=torch.float64, generator=gen)).requires_grad_(True)
    assert torch.autograd.gradcheck(R.quat_to_axis_angle, (q,))
    assert torch.autograd.gradcheck(lambda x: R.quat_to_euler(x, "ZXY"), (q,))
    assert torch.autograd.gradcheck(R.matrix_to_quat, (R.quat_to_matrix(q).detach().requires_grad_(True),))


@pytest.mark.parametrize("bad", ["xyz", "XYX", "XY", "ABC", "", None, "ZXYZ"])
def test_bad_order(bad):
    ang = torch.zeros(3)
    for fn in (R.euler_to_matrix, R.euler_to_quat):
        with pytest.raises(ValueError, match="Euler order"):
            fn(ang, bad)
    for fn in (R.matrix_to_euler,):
        with pytest.raises(KinemaError):
            fn(torch.eye(3), bad)
