"""Hitting kinematic constraints exactly (Kimodo Sec. 4.4: "a short optimization on the output motion
to ensure it *exactly* hits the kinematic constraints").

Two stages:

(a) ``optimise``: Adam on per-frame axis-angle deltas of every local rotation (post-multiplied) and on
    root translation offsets, minimising constraint residuals + closeness to the input + the
    acceleration of the change in joint positions (so the edit is smooth, the input's own motion is
    not penalised). Deltas are multiplied by a raised-cosine envelope around the constrained frames,
    so frames far from every constraint stay bit-for-bit unchanged.
(b) ``exact_pass``: sets what is constrained, in an order where later steps cannot undo earlier ones:
    1. full-body keyframes (rotation targets for every joint): exact local rotations and root
       translation, the corrections blended into neighbouring frames (kinema.postprocess.ik
       ``spread_corrections``, raised cosine over ``blend_seconds``);
    2. smoothed-root x/z waypoints: a smooth displacement of the root's x/z (small squared
       acceleration, exactly zero outside the Gaussian's reach of the waypoints) fitted so the
       smoothed pelvis passes through the waypoints while keyframe frames stay pinned (a regularised
       fit, kinema.postprocess.waypoints: isolated waypoints are met within 0.01 cm, dense paths within
       centimetres instead of inverting the smoothing);
    Targets beyond a limb's reach move the body by at most 0.5 m (kinema.postprocess.reach); what
    remains is reported in plain words (``unmet``, kinema.postprocess.residuals).
    3. end effectors: two-bone IK on the joint's chain for positions (toes move their foot rigidly via
       the leg chain), the joint's global rotation for rotations; not applied on keyframe frames,
       and never touching the pelvis, so steps 1-2 stay exact. (Positions of joints directly below
       the root have no two-bone chain: only the optimisation moves them.)

``hit_constraints`` runs both and reports residuals before/after per constraint kind.
"""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from kinema.geometry.rotations import (
    axis_angle_to_matrix,
    axis_angle_to_quat,
    matrix_to_quat,
    quat_between,
    quat_inverse,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_to_axis_angle,
    quat_to_matrix,
)
from kinema.kinematics import forward_kinematics_matrices, matmul3
from kinema.motion.contacts import contact_joints
from kinema.motion.core import Motion
from kinema.postprocess.ik import limb_chain, single_thread, solve_ik, spread_corrections
from kinema.postprocess.reach import clip_to_reach, reach_radius_seconds, reach_shift
from kinema.postprocess.residuals import constraint_residuals, unmet_targets
from kinema.postprocess.targets import PostTargets
from kinema.postprocess.waypoints import frame_envelope, root_waypoints, smoothing_matrix


def _support(targets: PostTargets, T: int, blend: float, root_reach: float, reach: float = 0.0) -> torch.Tensor:
    """(T,) envelope in [0, 1] of frames the optimisation may touch; ``reach`` (frames) widens it around
    position targets by the window over which an out-of-reach target may move the body."""
    frames = [f for table in (targets.joint_positions, targets.joint_rotations) for f, _ in table.values()]
    if targets.contacts is not None:
        frames.append(targets.contacts[0])
    env = frame_envelope(torch.cat(frames) if frames else torch.zeros(0, dtype=torch.long), T, blend + 1)
    if reach > blend and targets.joint_positions:
        pos = torch.cat([f for f, _ in targets.joint_positions.values()])
        env = torch.maximum(env, frame_envelope(pos, T, reach + 1))
    if targets.root_xz is not None:
        env = torch.maximum(env, frame_envelope(targets.root_xz[0], T, root_reach + blend + 1))
    return env


class CosineAdam:
    """Adam (torch.optim.Adam's defaults: betas 0.9 / 0.999, eps 1e-8) whose learning rate follows
    ``lr * 0.5 (1 + cos(pi k / iterations))`` at step k, i.e. torch.optim.Adam + LambdaLR.

    Hand-written because constructing the first ``torch.optim.Adam`` imports ``torch._dynamo``, which
    cost 1.1-1.2 s of the first constrained generate in a process. The update is torch's single-tensor
    CPU Adam operation for operation, so results match torch.optim.Adam + LambdaLR to float rounding
    (tests/test_postprocess_adam.py).
    """

    def __init__(self, params: list[torch.Tensor], lr: float, iterations: int,
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8):
        self.params, self.lr, self.iterations = list(params), lr, iterations
        self.betas, self.eps, self.k = betas, eps, 0
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]

    @torch.no_grad()
    def step(self, grads: tuple[torch.Tensor, ...] | list[torch.Tensor]) -> None:
        """One update of every parameter in place from its gradient (same order as ``params``)."""
        lr = self.lr * (0.5 * (1 + math.cos(math.pi * self.k / max(self.iterations, 1))))
        self.k += 1
        b1, b2 = self.betas
        step_size = lr / (1 - b1**self.k)
        bc2_sqrt = (1 - b2**self.k) ** 0.5
        for p, g, m, v in zip(self.params, grads, self.exp_avg, self.exp_avg_sq, strict=True):
            m.lerp_(g, 1 - b1)
            v.mul_(b2).addcmul_(g, g, value=1 - b2)
            p.addcdiv_(m, (v.sqrt() / bc2_sqrt).add_(self.eps), value=-step_size)


#: Adam steps of stage (a). The exact pass makes constraints exact whatever this is; the optimisation
#: only spreads the edit over the body. 80 -> 30 steps cut a 5-s motion's post-processing with two
#: waypoints and a hand target from ~0.9 s to ~0.4 s with no measurable change in jerk (731 vs 730 m/s^3).
OPTIMISE_ITERATIONS = 30


class _EditLoss:
    """The loss of stage (a) as a function of the parameters ``aa`` ``(T, J, 3)`` (axis-angle) and ``dr``
    ``(T, 3)`` (root offset), set up once for ``motion`` and ``targets``: constraint residuals in
    centimetres and degrees, the smoothed root through its waypoints, planted contacts that do not slide,
    the acceleration of the change in joint positions and closeness to the input. Only the ``sup``
    frames (where the envelope ``env`` is non-zero) are moved and run through forward kinematics."""

    def __init__(self, motion: Motion, targets: PostTargets, env: torch.Tensor, param_sigma: float,
                 closeness: float, smoothness: float) -> None:
        skel, T = motion.skeleton, motion.num_frames
        self.skel, self.T, self.J = skel, T, skel.num_joints
        self.closeness, self.smoothness, self.cm = closeness, smoothness, 0.01
        self.L0, self.r0 = motion.local_rotations, motion.root_translation
        _, P0 = motion.global_transforms()
        self.sup = sup = torch.nonzero(env > 0).flatten()  # frames the deltas may move
        slot = torch.full((T,), -1, dtype=torch.long)
        slot[sup] = torch.arange(sup.numel())
        self.L0m = quat_to_matrix(self.L0[sup])
        _, self.P0s = forward_kinematics_matrices(self.L0m, self.r0[sup], skel.offsets, skel.parents)
        pos = [(f, torch.full_like(f, j), v) for j, (f, v) in targets.joint_positions.items()]
        rot = [(f, torch.full_like(f, j), v) for j, (f, v) in targets.joint_rotations.items()]
        pf, self.pj, self.pv = (torch.cat(x) for x in zip(*pos, strict=True)) if pos else (None, None, None)
        qf, self.qj, qv = (torch.cat(x) for x in zip(*rot, strict=True)) if rot else (None, None, None)
        self.pf = None if pf is None else slot[pf]
        self.qf, self.Rv = (None, None) if qf is None else (slot[qf], quat_to_matrix(qv))
        self.pelvis = pelvis = skel.roles.get("pelvis", 0)
        self.S_sup = self.S_fixed = None
        if targets.root_xz is not None:
            S_rows = smoothing_matrix(T, targets.root_sigma * motion.fps)[targets.root_xz[0]]
            self.S_sup = S_sup = S_rows[:, sup]
            self.S_fixed = S_rows @ P0[:, pelvis][:, [0, 2]] - S_sup @ P0[sup, pelvis][:, [0, 2]] - targets.root_xz[1]
        self.planted = None
        if targets.contacts is not None:
            planted = torch.zeros(T, 4, dtype=torch.bool)
            planted[targets.contacts[0]] = targets.contacts[1] > 0.5
            self.planted = planted[1:] & planted[:-1]
            self.cj = torch.tensor(contact_joints(skel))
            self.xz0 = P0[:, self.cj][..., [0, 2]]
        # the deltas on the support frames: Gaussian-smoothed parameters (smooth by construction: Adam's
        # per-coordinate steps would otherwise leave jagged edits) times the envelope, one (Ns, T) matrix
        self.spread = env[sup, None] * smoothing_matrix(T, param_sigma)[sup]

    def deltas(self, aa: torch.Tensor, dr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The rotation and root deltas on the support frames."""
        return (self.spread @ aa.reshape(self.T, self.J * 3)).reshape(-1, self.J, 3), self.spread @ dr

    def __call__(self, aa: torch.Tensor, dr: torch.Tensor) -> torch.Tensor:
        skel, T, cm = self.skel, self.T, self.cm
        d_rot, d_root = self.deltas(aa, dr)
        G, P = forward_kinematics_matrices(matmul3(self.L0m, axis_angle_to_matrix(d_rot)), self.r0[self.sup] + d_root,
                                           skel.offsets, skel.parents)
        loss = P.new_zeros(())
        if self.pf is not None:
            loss = loss + (((P[self.pf, self.pj] - self.pv) / cm) ** 2).sum()
        if self.qf is not None:
            loss = loss + (((G[self.qf, self.qj] - self.Rv) ** 2).sum() / 2 / math.radians(1.0) ** 2)
        if self.S_sup is not None:
            loss = loss + (((self.S_sup @ P[:, self.pelvis][:, [0, 2]] + self.S_fixed) / cm) ** 2).sum()
        if self.planted is not None and T > 1:
            xz = self.xz0.index_copy(0, self.sup, P[:, self.cj][..., [0, 2]])
            loss = loss + (((xz[1:] - xz[:-1]) / cm) ** 2).sum(-1)[self.planted].sum()
        if T > 2:
            change = P.new_zeros(T, self.J, 3).index_copy(0, self.sup, P - self.P0s)
            acc = change[2:] - 2 * change[1:-1] + change[:-2]
            loss = loss + self.smoothness * ((acc / cm) ** 2).sum()
        loss = loss + self.closeness * ((d_rot / math.radians(1.0)) ** 2).sum()
        loss = loss + self.closeness * ((d_root / cm) ** 2).sum()
        return loss

    def applied(self, aa: torch.Tensor, dr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The input's local rotations and root translation with the deltas applied (every frame)."""
        d_rot, d_root = self.deltas(aa, dr)
        d_rot = torch.zeros(self.T, self.J, 3, dtype=torch.float64).index_copy(0, self.sup, d_rot)
        return quat_normalize(quat_mul(self.L0, axis_angle_to_quat(d_rot))), self.r0.index_add(0, self.sup, d_root)


def optimise(
    motion: Motion,
    targets: PostTargets,
    iterations: int = OPTIMISE_ITERATIONS,
    lr: float = 0.01,
    blend_seconds: float = 0.3,
    closeness: float = 1e-3,
    smoothness: float = 0.1,
) -> tuple[Motion, dict]:
    """Stage (a): a short Adam optimisation pulling the motion towards the targets (float64 in/out).

    The deltas vanish outside the envelope of the constrained frames, so the loss (`_EditLoss`) runs
    forward kinematics on those frames only (the others keep their input positions, entering the
    root-path and contact terms as constants), with rotation matrices, one matrix product per depth level
    (kinema.kinematics.forward_kinematics_matrices): the same loss as joint-by-joint quaternion FK over
    every frame, to float rounding, at a fraction of the tensor operations. A rotation target's term
    ``4 (1 - <q, q_target>^2)`` is written ``|R - R_target|_F^2 / 2`` (both are 4 sin^2(angle / 2))."""
    skel, T, fps = motion.skeleton, motion.num_frames, motion.fps
    env = _support(targets, T, blend_seconds * fps, math.ceil(3 * targets.root_sigma * fps))
    loss_fn = _EditLoss(motion, targets, env, max(blend_seconds * fps / 4, 0.5), closeness, smoothness)
    aa = torch.zeros(T, skel.num_joints, 3, dtype=torch.float64, requires_grad=True)
    dr = torch.zeros(T, 3, dtype=torch.float64, requires_grad=True)
    opt = CosineAdam([aa, dr], lr=lr, iterations=iterations)
    history = []
    moves = loss_fn.sup.numel() > 0
    with single_thread():
        for _ in range(iterations if moves else 0):
            loss = loss_fn(aa, dr)
            opt.step(torch.autograd.grad(loss, [aa, dr]))
            history.append(float(loss.detach()))
    with torch.no_grad():
        L, r = loss_fn.applied(aa, dr)
        final = float(loss_fn(aa, dr)) if iterations and moves else 0.0
    info = {"iterations": len(history), "loss_start": history[0] if history else 0.0, "loss_end": final}
    return Motion(skel, fps, r, L, motion.foot_contacts), info


def _lookup(pair, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Values ``(K, C)`` of a (frames, values) target at ``frames`` and whether each is present
    (missing ones are zero; the last value wins for repeated frames)."""
    index = {int(k): i for i, k in enumerate(pair[0].tolist())}
    rows = torch.tensor([index.get(int(k), -1) for k in frames.tolist()], dtype=torch.long)
    present = rows >= 0
    values = pair[1][rows.clamp(min=0)] if pair[1].shape[0] else pair[1].new_zeros(len(rows), pair[1].shape[1])
    return torch.where(present[:, None], values, torch.zeros_like(values)), present


def _keep_out(frames: torch.Tensor, values: torch.Tensor, blocked: torch.Tensor):
    keep = ~blocked[frames]
    return frames[keep], values[keep]


#: alternations of reach shift and waypoint displacement in the exact pass
REACH_ROUNDS = 4


def exact_pass(motion: Motion, targets: PostTargets, blend_seconds: float = 0.3) -> Motion:
    """Stage (b): set constrained quantities exactly, blending the edits into neighbouring frames."""
    radius = max(blend_seconds * motion.fps, 1.0)
    L, r, pinned = _pin_keyframes(motion, targets, radius)
    r = _move_body(motion.skeleton, motion.fps, L, r, targets, pinned, radius)
    m = Motion(motion.skeleton, motion.fps, r, L, motion.foot_contacts)
    skel = motion.skeleton
    for j in sorted(set(targets.joint_positions) | set(targets.joint_rotations), key=lambda j: skel.depths[j]):
        m = _hit_end_effector(m, j, targets, pinned, radius)
    return m


def _pin_keyframes(motion: Motion, targets: PostTargets, radius: float):
    """Step 1: full-body keyframes and root-joint positions set exactly. Returns the local rotations, the
    root translation and the frames now pinned (``(T,)`` bool: later steps leave them alone)."""
    skel, T = motion.skeleton, motion.num_frames
    L, r = motion.local_rotations.clone(), motion.root_translation.clone()
    J, root = skel.num_joints, 0
    parents = [max(p, 0) for p in skel.parents]
    F = targets.full_body_frames(J)
    if F.numel():
        Gt = _keyframe_rotations(skel, motion.global_rotations[F], targets, F)  # (K, J, 4)
        Lt = quat_mul(quat_inverse(Gt[:, parents]), Gt)
        Lt[:, root] = Gt[:, root]
        corr = quat_to_axis_angle(quat_mul(quat_inverse(L[F]), Lt))
        field, _ = spread_corrections(F, corr.reshape(F.numel(), -1), T, radius)
        L = quat_normalize(quat_mul(L, axis_angle_to_quat(field.reshape(T, J, 3))))
    pinned = torch.zeros(T, dtype=torch.bool)
    pinned[F] = True
    root_frames, root_shift = F, torch.zeros(F.numel(), 3, dtype=torch.float64)
    if root in targets.joint_positions:
        f, v = targets.joint_positions[root]
        root_frames, root_shift = torch.cat([root_frames, f]), torch.cat([root_shift, v - r[f]])
        pinned[f] = True
    if root_frames.numel():
        shift, _ = spread_corrections(root_frames, root_shift, T, radius)
        r = r + shift
    return L, r, pinned


def _move_body(skel, fps: float, L: torch.Tensor, r: torch.Tensor, targets: PostTargets, pinned: torch.Tensor,
               radius: float) -> torch.Tensor:
    """Steps 1b + 2, the root translation moved: targets beyond a limb's reach move the body towards them
    (a narrow bump of the root, kinema.postprocess.reach); smoothed-root waypoints then get a broad
    minimum-acceleration x/z displacement. A bump shifts the smoothed root a little, so the two alternate a
    few rounds: with both a waypoint and an end effector on one frame, this converges to a pose satisfying
    both."""
    has_root = targets.root_xz is not None and targets.root_xz[0].numel()
    for _ in range(REACH_ROUNDS if has_root else 1):
        if targets.joint_positions:
            r = r + reach_shift(Motion(skel, fps, r, L), targets.joint_positions, pinned, radius)
        if has_root:
            r = root_waypoints(skel, L, r, targets, fps, radius, pinned)
    return r


def _hit_end_effector(m: Motion, j: int, targets: PostTargets, pinned: torch.Tensor, radius: float) -> Motion:
    """Step 3: joint ``j``'s position and rotation targets set by IK, never on pinned frames, never by
    moving the root translation (a toe moves its whole foot: the ankle takes the toe's shift)."""
    skel, T, root = m.skeleton, m.num_frames, 0
    toes = {skel.roles.get(f"{s}_toe"): s for s in ("left", "right")}
    G, P = m.global_transforms()
    mask = (~pinned)[:, None].to(torch.float64)
    rot_field = rot_env = None
    if j in targets.joint_rotations:
        f, q = _keep_out(*targets.joint_rotations[j], pinned)
        if f.numel():
            rc = quat_to_axis_angle(quat_mul(q, quat_inverse(G[f, j])))
            rot_field, rot_env = spread_corrections(f, rc, T, radius)
            rot_field, rot_env = rot_field * mask, rot_env * mask[:, 0]
    pos = _keep_out(*targets.joint_positions[j], pinned) if j in targets.joint_positions else None
    if pos is not None and pos[0].numel() and j != root and (j in toes or skel.depths[j] >= 2):
        f, v = pos
        shift, env = spread_corrections(f, v - P[f, j], T, radius)
        shift, env = shift * mask, env * mask[:, 0]
        end_rot = None
        if rot_field is not None:
            env = torch.maximum(env, rot_env)
            end_rot = quat_mul(axis_angle_to_quat(rot_field), G[:, j])
        if j in toes:  # move the whole foot: the ankle takes the toe's shift, foot rotation kept
            chain = limb_chain(skel, f"{toes[j]}_leg")
            m = solve_ik(m, chain, P[:, chain[2]] + shift, weight=(env > 0).to(torch.float64))
            if end_rot is not None:
                m = _set_global_rotation(m, j, end_rot, rot_env)
            return m
        return solve_ik(m, j, P[:, j] + shift, weight=(env > 0).to(torch.float64), end_rotation=end_rot)
    if rot_field is not None:
        m = _set_global_rotation(m, j, quat_mul(axis_angle_to_quat(rot_field), G[:, j]), rot_env)
    return m


def _keyframe_rotations(skel, G_now: torch.Tensor, targets: PostTargets, F: torch.Tensor) -> torch.Tensor:
    """Global rotations ``(K, J, 4)`` of full-body keyframes ``F``: the rotation target where one is
    given, else derived from position targets by turning the joint (from its current rotation
    ``G_now``) so its bones point at its children's targets: shortest arc for one child (keeps the
    current twist), a least-squares fit (Kabsch) for several; otherwise the current rotation."""
    rots = G_now.clone()
    for j in range(skel.num_joints):
        kids = list(skel.children[j])
        pos_ok = torch.zeros(F.numel(), dtype=torch.bool)
        if kids and all(c in targets.joint_positions for c in [j, *kids]):
            pj, pos_ok = _lookup(targets.joint_positions[j], F)
            want = [_lookup(targets.joint_positions[c], F) for c in kids]
            for _, ok in want:
                pos_ok = pos_ok & ok
            want = torch.stack([v - pj for v, _ in want], dim=1)  # (K, C, 3)
            have = quat_rotate(G_now[:, j, None], skel.offsets[kids].to(want.dtype))  # (K, C, 3)
            if len(kids) == 1:
                turn = quat_between(have[:, 0], want[:, 0])
            else:
                U, _, Vh = torch.linalg.svd(want.transpose(1, 2) @ have)  # sum of want have^T
                d = torch.sign(torch.linalg.det(U @ Vh))
                D = torch.diag_embed(torch.stack([torch.ones_like(d), torch.ones_like(d), d], dim=-1))
                turn = matrix_to_quat(U @ D @ Vh)
            rots[:, j] = torch.where(pos_ok[:, None], quat_normalize(quat_mul(turn, G_now[:, j])), rots[:, j])
        if j in targets.joint_rotations:
            q, ok = _lookup(targets.joint_rotations[j], F)
            rots[:, j] = torch.where(ok[:, None], q, rots[:, j])
    return rots


def _set_global_rotation(m: Motion, j: int, G_new: torch.Tensor, env: torch.Tensor) -> Motion:
    """Set joint ``j``'s global rotation where ``env > 0`` (its descendants follow)."""
    G = m.global_rotations
    p = m.skeleton.parents[j]
    L = m.local_rotations.clone()
    local = G_new if p < 0 else quat_mul(quat_inverse(G[:, p]), G_new)
    L[:, j] = torch.where((env > 0)[:, None], quat_normalize(local), L[:, j])
    return Motion(m.skeleton, m.fps, m.root_translation, L, m.foot_contacts)


def hit_constraints(
    motion: Motion,
    targets: PostTargets,
    iterations: int = OPTIMISE_ITERATIONS,
    lr: float = 0.01,
    blend_seconds: float = 0.3,
    closeness: float = 1e-3,
    smoothness: float = 0.1,
) -> tuple[Motion, dict]:
    """Short optimisation then exact pass; returns the motion (input dtype) and a report with
    ``before``/``after`` residuals (see ``constraint_residuals``), ``unmet`` (targets still missed, in
    words), the optimisation losses, and the largest joint displacement (cm) on unconstrained frames and
    outside every blend window."""
    targets = targets.validate(motion)
    m0 = motion.to(torch.float64)
    with single_thread():
        before = constraint_residuals(m0, targets)
        aim = replace(targets, joint_positions=clip_to_reach(m0, targets.joint_positions))
        m, info = optimise(m0, aim, iterations, lr, blend_seconds, closeness, smoothness)
        m = exact_pass(m, aim, blend_seconds)
        after = constraint_residuals(m, targets)
    T = m0.num_frames
    constrained = torch.zeros(T, dtype=torch.bool)
    for table in (targets.joint_positions, targets.joint_rotations):
        for f, _ in table.values():
            constrained[f] = True
    if targets.root_xz is not None:
        constrained[targets.root_xz[0]] = True
    change = (m.positions - m0.positions).norm(dim=-1).max(dim=-1).values * 100  # (T,) cm
    fps = m0.fps
    outside = _support(targets, T, blend_seconds * fps, math.ceil(3 * targets.root_sigma * fps),
                       reach_radius_seconds() * fps) == 0
    report = {
        "before": before,
        "after": after,
        "unmet": unmet_targets(m, targets),
        "optimisation": info,
        "max_change_unconstrained_cm": float(change[~constrained].max()) if (~constrained).any() else 0.0,
        "max_change_outside_blend_cm": float(change[outside].max()) if outside.any() else 0.0,
    }
    out = Motion(m.skeleton, m.fps, m.root_translation, m.local_rotations, motion.foot_contacts)
    return out.to(motion.dtype), report
