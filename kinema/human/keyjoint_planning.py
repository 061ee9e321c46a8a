"""Keyjoint planning (SFControl Sec. 3.1 + 3.2): plan the keyjoints first, then pose the body on them.

Stage 1 samples a dense keyjoint trajectory ``(B, T, 20)`` (kinema.representation.keyjoint: pelvis,
head, hands, ankles in world metres, Y up, then the heading) from the small keyjoint denoiser
(kinema.model.keyjoint). The user's constraints reach it as sparse keyjoint targets (every joint
position a constraint pins: end effectors, full-body keyframes) plus smoothed-root x/z targets
(waypoints, paths, the root given with an end effector). After every DDIM step the clean estimate is
bent towards the targets (:func:`displace_keyjoints`) and the targets are imputed exactly.

Stage 2 runs kinema's body sampler with the user's own feature targets untouched (so every constraint
type keeps its meaning) and the planned trajectory filled in wherever the user set nothing
(:func:`with_keyjoint_plan`): the smoothed pelvis as a dense root path, the heading, and the positions
of the targeted keyjoints on every frame. One refinement pass then re-samples the body from the same
noise with those trajectories moved on by the miss the first pass left (:data:`REFINE_PASSES`).

Why the displacement (measured on 8 sparse-protocol test crops, raw, keyjoint model at step 3335):
with imputation alone the small model's own trajectory ignored far targets and jumped onto them at the
target frame (keyjoint acceleration next to targets 103 m/s^2, ground truth about 6; stage-1 keyjoints
51 cm from ground truth; control error after completion 34.6 cm). Translating the whole body by the
targets' interpolated x/z miss and spreading each joint's remaining miss over a Gaussian brought that
to 28 m/s^2, 15 cm and 8.8 cm; without the translation, 14.7 cm.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from importlib.resources import files
from pathlib import Path

import torch

from kinema.constraints import EndEffectorConstraint
from kinema.constraints.types import resolve_joint
from kinema.diffusion.sampler import DDIMSampler, spaced_timesteps
from kinema.errors import KinemaError
from kinema.human.keyjoints import KeyjointTargets, gaussian_spread
from kinema.human.sampling import SampleSettings, SampleTargets, sample_features
from kinema.model.keyjoint import KeyjointDenoiser, load_keyjoint_model
from kinema.model.loading import LoadedModel
from kinema.model.precision import set_precision
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time
from kinema.representation.flat import FlatRepresentation
from kinema.representation.keyjoint import (
    HEADING,
    KEYJOINT_DIM,
    NUM_KEYJOINTS,
    POSITIONS,
    keyjoint_indices,
    keyjoint_positions,
)

#: DDIM steps of the keyjoint stage (20 measured as good as 50 on the sparse protocol: 8.79 vs 8.78 cm)
KEYJOINT_STEPS = 20
KEYJOINT_TEXT_WEIGHT = 2.0
#: Gaussian (seconds) over which a keyjoint's remaining miss is spread (0.15 / 0.3 / 0.6 s: 9.3 / 8.8 /
#: 8.7 cm on the sparse protocol's 8 crops, i.e. within noise; 0.3 s keeps the bend local)
KEYJOINT_SIGMA_SECONDS = 0.3
#: Gaussian (seconds) over the finished trajectory: the small model's keyjoints shake (acceleration far
#: from targets 4-5 x ground truth), and the body stage copies that into the pelvis; 0.1 s took the
#: sparse protocol's jerk 310 -> 92 (direct 277) and its control error 8.9 -> 8.5 cm, and on the
#: suite's end-effector cases jerk 835 -> 204
KEYJOINT_SMOOTH_SECONDS = 0.1
#: Gaussian (seconds) of the displacement that bends the smoothed trajectory back onto the targets
FINAL_SIGMA_SECONDS = 0.15
#: Refinement passes of stage 2: the body follows a planned trajectory only to about 8 cm (short of it,
#: like a single keyframed joint), so each pass re-samples the body from the same noise with the plan
#: moved on by the miss it left (smoothed over REFINE_SIGMA_SECONDS, so nothing snaps). Measured with
#: the keyjoint model at step 6000: sparse protocol 8.37 -> 5.03 cm (1 pass) -> 3.83 cm (2 passes),
#: suite end-effector cases 9.45 -> 6.67 cm (1 pass); each pass costs one more stage-2 run.
REFINE_PASSES = 1
REFINE_SIGMA_SECONDS = 0.15
#: share of the DDIM steps a refinement pass runs: it starts from the previous pass's motion re-noised to
#: that level (as a timeline's join windows do), not from pure noise (docs/speed.md, "Keyjoint planning
#: by default")
REFINE_STRENGTH = 1.0
#: share of the DDIM steps the first body pass runs when a refinement pass follows: that pass only
#: measures the body's miss, which the refinement then aims past. Sparse protocol, 16 test crops, bf16,
#: 50 steps: 1.0 / 0.5 / 0.4 / 0.3 of the steps gave 4.14 / 4.57 / 4.76 / 5.10 cm at 2.06 / 1.56 / 1.44 /
#: 1.30x the CPU time of direct sampling (19.96 cm). On the bench's drifting walk (2 seeds, worst target)
#: a refinement from the first pass re-noised instead (REFINE_STRENGTH 0.5 / 0.3) missed by 9.7 / 9.2-9.9
#: cm against 7.5-8.7 cm for share 0.4 at about the same time (docs/speed.md)
FIRST_PASS_SHARE = 0.5


def plans_by_default(constraints, skeleton) -> bool:
    """Whether a call with these constraint objects is keyjoint-planned when it names no keyjoint model:
    every constraint is an end-effector target with positions only (no rotation, no smoothed root), and
    one at least is on a keyjoint (pelvis, head, hands, ankles). A root path, a keyframe, foot contacts, a
    smoothed root or a rotation given with a target leave the call direct: SFControl's setting is sparse
    joint positions alone, and the plan carries positions only (with it the suite's end-effector rotation
    error rose 30.7 -> 44.3 degrees, docs/constraints.md)."""
    if not constraints:
        return False
    keys = set(keyjoint_indices(skeleton))
    on_key = False
    for c in constraints:
        if not isinstance(c, EndEffectorConstraint) or c.positions is None or c.rotations is not None:
            return False
        if c.smooth_root_2d is not None:
            return False
        on_key = on_key or resolve_joint(skeleton, c.joint) in keys
    return on_key


def shipped_planner() -> bool:
    """Whether this install ships the default keyjoint model (kinema/assets/models/keyjoint)."""
    return (Path(str(files("kinema") / "assets" / "models" / "keyjoint")) / "keyjoint.json").is_file()


class KeyjointPlanTargets:
    """Stage-1 targets read off the body sampler's targets: ``k_tgt``/``k_mask (B, T, 20)`` (a joint is
    a target where all three coordinates are known in world space) and the smoothed-root x/z
    ``root (B, T, 2)`` where ``root_mask (B, T)``."""

    def __init__(self, targets: SampleTargets, rep: FlatRepresentation, num_frames: int):
        B, T = targets.batch_size, num_frames
        self.k_tgt = torch.zeros(B, T, KEYJOINT_DIM)
        self.k_mask = torch.zeros(B, T, KEYJOINT_DIM)
        self.root = torch.zeros(B, T, 2)
        self.root_mask = torch.zeros(B, T, dtype=torch.bool)
        if targets.mask is None and not targets.has_world:
            return
        x_tgt = torch.zeros(B, T, rep.dim) if targets.x_tgt is None else torch.nan_to_num(targets.x_tgt.float())
        mask = torch.zeros(B, T, rep.dim) if targets.mask is None else targets.mask.float()
        world = targets.has_world
        keys = KeyjointTargets(
            rep, x_tgt, mask, targets.world_xz if world else None, targets.world_mask if world else None
        )
        idx = keyjoint_indices(rep.skeleton)
        known = keys.mask[:, :, idx].amin(-1) > 0  # (B, T, 6)
        m = known[..., None].expand(B, T, NUM_KEYJOINTS, 3).float()
        self.k_tgt[..., POSITIONS] = (keys.pos[:, :, idx].float() * m).flatten(-2)
        self.k_mask[..., POSITIONS] = m.flatten(-2)
        rx, rz = rep.root_xz
        self.root = x_tgt[..., [rx, rz]]
        self.root_mask = (mask[..., rx] > 0) & (mask[..., rz] > 0)


def _hold_interp(r: torch.Tensor, has: torch.Tensor) -> torch.Tensor:
    """``r (B, T, C)`` given where ``has (B, T)``: piecewise-linear in time between given frames, held
    before the first and after the last; zeros for a row with none."""
    B, T, _ = r.shape
    time = torch.arange(T).view(1, T).expand(B, T)
    prev = torch.where(has, time, -1).cummax(dim=1).values
    nxt = torch.where(has, time, T).flip(1).cummin(dim=1).values.flip(1)
    first = torch.where(has, time, T).amin(dim=1, keepdim=True).expand(B, T)
    last = torch.where(has, time, -1).amax(dim=1, keepdim=True).expand(B, T)
    prev = torch.where(prev < 0, first, prev).clamp(0, T - 1)
    nxt = torch.where(nxt >= T, last, nxt).clamp(0, T - 1)
    span = (nxt - prev).clamp_min(1).to(r.dtype)
    w = torch.where(nxt > prev, (time - prev).to(r.dtype) / span, torch.zeros_like(span))[..., None]
    out = (1 - w) * r.gather(1, prev[..., None].expand_as(r)) + w * r.gather(1, nxt[..., None].expand_as(r))
    return out * has.any(dim=1).view(B, 1, 1).to(r.dtype)


def displace_keyjoints(
    k: torch.Tensor, plan: KeyjointPlanTargets, *, sigma_frames: float, root_sigma_frames: float
) -> torch.Tensor:
    """Keyjoints ``k (B, T, 20)`` (metres) bent smoothly towards ``plan``'s targets.

    First the whole body moves in x/z by an interpolated miss (per target frame: the smoothed-root miss
    where a root target exists, else the targeted joints' mean x/z miss; piecewise-linear between target
    frames, held beyond them), so a far target moves the whole body, not one joint; then each joint's
    remaining miss is spread over neighbouring frames with a Gaussian of ``sigma_frames``."""
    P = keyjoint_positions(k)
    G = keyjoint_positions(plan.k_tgt).to(k)
    M = keyjoint_positions(plan.k_mask)[..., 0] > 0  # (B, T, 6)
    cnt = M.sum(-1)
    res = ((G - P) * M[..., None])[..., [0, 2]].sum(2) / cnt.clamp_min(1)[..., None]  # (B, T, 2)
    root_miss = plan.root.to(k) - smooth_time(P[..., 0, [0, 2]], root_sigma_frames)
    res = torch.where(plan.root_mask[..., None], root_miss, res)
    shift = _hold_interp(res, (cnt > 0) | plan.root_mask)
    P = P + torch.stack([shift[..., 0], torch.zeros_like(shift[..., 0]), shift[..., 1]], dim=-1)[:, :, None]
    P = P + gaussian_spread((G - P) * M[..., None], M, sigma_frames)
    return torch.cat([P.flatten(-2), k[..., HEADING]], dim=-1)


@torch.no_grad()
def sample_keyjoints(
    planner: KeyjointPlanner,
    text_emb: torch.Tensor | None,
    c_dir: torch.Tensor,
    plan: KeyjointPlanTargets,
    *,
    fps: float,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Dense keyjoints ``(B, T, 20)`` (metres) meeting ``plan``'s joint targets exactly, in
    ``planner.steps`` DDIM steps of ``planner.model`` / ``planner.sampler``.

    Classifier-free text guidance ``x0 = D_none + w (D_text - D_none)`` (``w = planner.w_text``; both
    branches see the targets), then :func:`displace_keyjoints` (``planner.sigma_seconds = 0`` turns it
    off: imputation alone), then the targets are imputed into the clean estimate. The result is low-passed
    with a Gaussian of ``planner.smooth_seconds`` (0 = off), bent back onto the targets and imputed once more."""
    model, sampler, steps = planner.model, planner.sampler, planner.steps
    w_text, sigma_seconds, smooth_seconds = planner.w_text, planner.sigma_seconds, planner.smooth_seconds
    B, T, C = plan.k_tgt.shape
    k_mask = plan.k_mask
    tgt = model.normalize(plan.k_tgt) * k_mask
    text = torch.zeros(B, model.config.text_dim) if text_emb is None else text_emb.float().expand(B, -1)
    x = torch.randn((B, T, C), generator=generator)
    ts = spaced_timesteps(sampler.num_train_steps, steps, sampler.timestep_spacing)
    w = w_text if text_emb is not None else 0.0
    for t, prev in zip(ts, ts[1:] + [-1], strict=True):
        tb = torch.full((2 * B,), t, dtype=torch.long)
        both = model(
            torch.cat([x, x]),
            tb,
            torch.cat([torch.zeros_like(text), text]),
            torch.cat([c_dir, c_dir]),
            torch.cat([tgt, tgt]),
            torch.cat([k_mask, k_mask]),
        )
        x0 = both[:B] + w * (both[B:] - both[:B])
        if sigma_seconds > 0:
            x0 = model.normalize(
                displace_keyjoints(
                    model.denormalize(x0),
                    plan,
                    sigma_frames=sigma_seconds * fps,
                    root_sigma_frames=DEFAULT_ROOT_SIGMA_SECONDS * fps,
                )
            )
        x0 = k_mask * tgt + (1 - k_mask) * x0
        x = sampler.step_to(x0, t, prev, x)
    keys = model.denormalize(x)
    if smooth_seconds > 0:
        keys = smooth_time(keys, smooth_seconds * fps)
        keys = displace_keyjoints(
            keys, plan, sigma_frames=FINAL_SIGMA_SECONDS * fps, root_sigma_frames=DEFAULT_ROOT_SIGMA_SECONDS * fps
        )
    return plan.k_mask * plan.k_tgt + (1 - plan.k_mask) * keys


def with_keyjoint_plan(
    targets: SampleTargets,
    keys: torch.Tensor,
    plan: KeyjointPlanTargets,
    rep: FlatRepresentation,
    *,
    override: bool = False,
) -> SampleTargets:
    """The body sampler's targets with the planned keyjoints ``keys (B, T, 20)`` filled in wherever the
    user's own targets leave a channel free: the smoothed pelvis x/z (the root's definition) as the root,
    the heading, and the y (``joint_pos``) and world x/z (the world store the sampler re-targets against
    its root after every step) of each keyjoint that has a position target somewhere in ``plan``.

    Only targeted keyjoints: on the suite's end-effector cases, also imposing the others (the planned
    pelvis, head, free hand and feet) raised the raw end-effector error 9.6 -> 12.6 cm (the body stage
    follows a planned trajectory to about 8 cm, and the untargeted ones only add disagreement); on the
    sparse protocol, where most keyjoints are targeted somewhere, the two were equal (8.45 / 8.49 cm).
    With ``override`` the planned keyjoints' positions replace the user's own on every frame (the
    refinement pass of :func:`sample_with_keyjoint_plan` aims them past the targets by the body's miss)."""
    B, T, _ = keys.shape
    x_tgt = torch.zeros(B, T, rep.dim) if targets.x_tgt is None else torch.nan_to_num(targets.x_tgt.float()).clone()
    mask = torch.zeros(B, T, rep.dim) if targets.mask is None else targets.mask.float().clone()
    J = rep.num_joints
    wxz = torch.zeros(B, T, J, 2) if targets.world_xz is None else targets.world_xz.float().clone()
    wm = torch.zeros(B, T, J) if targets.world_mask is None else targets.world_mask.float().clone()
    P = keyjoint_positions(keys).float()
    rxz = rep.root_xz
    root = smooth_time(P[..., 0, [0, 2]], DEFAULT_ROOT_SIGMA_SECONDS * rep.fps)
    free = (mask[..., rxz] == 0).all(-1, keepdim=True)
    x_tgt[..., rxz] = torch.where(free, root, x_tgt[..., rxz])
    mask[..., rxz] = torch.where(free, 1.0, mask[..., rxz])
    heading = keys[..., HEADING].float()
    heading = heading / heading.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    hfree = (mask[..., rep.heading] == 0).all(-1, keepdim=True)
    x_tgt[..., rep.heading] = torch.where(hfree, heading, x_tgt[..., rep.heading])
    mask[..., rep.heading] = torch.where(hfree, 1.0, mask[..., rep.heading])
    ix, iy = rep.joint_pos_axis(0).tolist(), rep.joint_pos_axis(1).tolist()
    planned = keyjoint_positions(plan.k_mask).amax(dim=(1, 3)) > 0  # (B, 6)
    iz = rep.joint_pos_axis(2).tolist()
    for c, j in enumerate(keyjoint_indices(rep.skeleton)):
        jfree = (mask[..., iy[j]] == 0) & (mask[..., ix[j]] == 0) & (wm[..., j] == 0) & planned[:, c, None]
        if override:  # root-relative x/z targets give way to the world store
            jfree = planned[:, c, None].expand_as(jfree)
            mask[..., ix[j]] = torch.where(jfree, 0.0, mask[..., ix[j]])
            mask[..., iz[j]] = torch.where(jfree, 0.0, mask[..., iz[j]])
        x_tgt[..., iy[j]] = torch.where(jfree, P[..., c, 1], x_tgt[..., iy[j]])
        mask[..., iy[j]] = torch.where(jfree, 1.0, mask[..., iy[j]])
        wxz[..., j, :] = torch.where(jfree[..., None], P[..., c, [0, 2]], wxz[..., j, :])
        wm[..., j] = torch.where(jfree, 1.0, wm[..., j])
    return replace(targets, x_tgt=x_tgt, mask=mask, world_xz=wxz, world_mask=wm)


@dataclass(frozen=True)
class KeyjointPlanner:
    """A loaded keyjoint denoiser with its DDIM sampler and training facts (``info``), as
    ``KinemaModel.generate(..., keyjoint_model=...)`` uses it, and the stage-1 sampler settings
    :func:`sample_keyjoints` reads (steps, text weight, displacement and smoothing seconds)."""

    model: KeyjointDenoiser
    sampler: DDIMSampler
    info: dict
    steps: int = KEYJOINT_STEPS
    refine: int = REFINE_PASSES
    refine_strength: float = REFINE_STRENGTH
    first_pass_share: float = FIRST_PASS_SHARE
    w_text: float = KEYJOINT_TEXT_WEIGHT
    sigma_seconds: float = KEYJOINT_SIGMA_SECONDS
    smooth_seconds: float = KEYJOINT_SMOOTH_SECONDS

    @staticmethod
    def check(name_or_path: str | Path) -> Path:
        """The folder ``name_or_path`` names (``"default"``: kinema/assets/models/keyjoint), or a
        one-line KinemaError when it holds no keyjoint model."""
        shipped = str(name_or_path) == "default"
        path = Path(str(files("kinema") / "assets" / "models" / "keyjoint")) if shipped else Path(name_or_path)
        if not (path / "keyjoint.json").is_file():
            what = (
                "this kinema install ships no keyjoint model"
                if shipped
                else "no keyjoint.json (not a keyjoint model folder)"
            )
            raise KinemaError(f"{path}: {what}")
        return path

    @classmethod
    def load(cls, name_or_path: str | Path, precision: str = "fp32") -> KeyjointPlanner:
        """``"default"`` (the keyjoint model shipped in kinema/assets/models/keyjoint) or a model folder
        written by ``python -m kinema.train.keyjoint`` (its ``export``); ``precision`` as the body model's
        (kinema.model.precision)."""
        model, info = load_keyjoint_model(cls.check(name_or_path))
        return cls(set_precision(model, precision), DDIMSampler(), info)


def sample_with_keyjoint_plan(
    loaded: LoadedModel,
    text_emb: torch.Tensor | None,
    targets: SampleTargets,
    settings: SampleSettings,
    *,
    planner: KeyjointPlanner,
    generator: torch.Generator | None = None,
    **kwargs,
) -> torch.Tensor:
    """Unnormalised body features ``(B, T, D)``: stage 1 plans the keyjoints from ``targets``, stage 2
    is :func:`kinema.human.sampling.sample_features` on the targets with the plan filled in
    (``kwargs`` go there: progress, on_step...), then ``planner.refine`` passes re-sample the body from
    the same noise with the planned keyjoints moved on by the (smoothed) miss the previous pass left;
    ``on_step`` counts the steps of all passes."""
    sampler, rep = loaded.sampler, loaded.representation
    plan = KeyjointPlanTargets(targets, rep, settings.num_frames)
    keys = sample_keyjoints(planner, text_emb, targets.c_dir.float(), plan, fps=rep.fps, generator=generator)
    noise = None if generator is None else generator.get_state()
    passes, count = 1 + planner.refine, kwargs.pop("on_step", None)
    refine = replace(settings, strength=planner.refine_strength)

    def run(full: SampleTargets, k: int, how: SampleSettings) -> torch.Tensor:
        step = None if count is None else (lambda d, n: count(k * n + d, passes * n))
        if noise is not None:  # every pass starts from the same noise
            generator.set_state(noise)
        return sample_features(loaded, text_emb, full, how, generator=generator, on_step=step, **kwargs)

    first = settings
    if planner.refine and planner.first_pass_share < 1:
        steps = settings.steps or sampler.num_inference_steps
        first = replace(settings, steps=max(1, round(steps * planner.first_pass_share)))
    feats = run(with_keyjoint_plan(targets, keys, plan, rep), 0, first)
    idx, aim = keyjoint_indices(rep.skeleton), keys.clone()
    for k in range(1, passes):
        miss = keys[..., POSITIONS] - rep.pose(feats)[:, :, idx].flatten(-2).to(keys)
        aim[..., POSITIONS] += smooth_time(miss, REFINE_SIGMA_SECONDS * rep.fps)
        full = with_keyjoint_plan(targets, aim, plan, rep, override=True)
        if refine.strength < 1:  # re-noise the previous pass's motion instead of starting from pure noise
            full = replace(full, start=feats)
        feats = run(full, k, refine if refine.strength < 1 else settings)
    return feats
