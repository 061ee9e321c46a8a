"""The Kimodo training loss (paper Sec. 4.3, Eq. 1) on normalised motion features.

``L = g1 |r_p| + g2 |r_a| + g3 |j_p| + g4 |j_v| + g5 |j_a| + g6 |f| + g7 |FK(j_a) - j_p|`` where each
``|.|`` is a smooth L1 between prediction and ground truth (``torch.nn.functional.smooth_l1_loss``,
quadratic below ``beta``, linear above). The first six terms compare *normalised* feature groups (see
kinema.representation.kimodo_features for the layout and kinema.representation.stats for the normalisation). The FK term
turns the predicted global 6D rotations into joint positions and compares them with the ground-truth
joint positions in metres, so that rotations are trained to agree with positions.

Every term is a mean over valid frames and over the channels of its group; padded frames (variable
length batches) contribute nothing, not even through NaN or inf values, and receive zero gradient.
Shapes: ``pred``/``target`` ``(B, T, D)`` normalised, ``pad_mask`` ``(B, T)`` bool, True = valid frame.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F

from kinema.kinematics import positions_from_sixd
from kinema.motion.contacts import contact_joints
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.skeleton import Skeleton

#: Loss terms in the order of Eq. 1 (the first six are feature groups of FeatureLayout).
TERMS = ("root_pos", "heading", "joint_pos", "joint_vel", "joint_rot", "contacts", "fk")


@dataclass(frozen=True)
class LossWeights:
    """gamma_1..gamma_7 of Eq. 1 (paper values) plus the smooth L1 settings.

    ``beta`` is the smooth L1 transition point for the normalised terms (in units of one feature
    standard deviation). The FK term works in metres: errors are divided by ``fk_unit`` metres before
    the smooth L1 with ``fk_beta``, so with the defaults it is quadratic below 10 cm and grows by one
    per extra decimetre (a decimetre is about one standard deviation of a joint position channel, so
    the FK term has a scale comparable to the normalised joint_pos term).
    """

    root_pos: float = 10.0  # gamma_1
    heading: float = 2.0  # gamma_2
    joint_pos: float = 10.0  # gamma_3
    joint_vel: float = 3.0  # gamma_4
    joint_rot: float = 10.0  # gamma_5
    contacts: float = 4.0  # gamma_6
    fk: float = 5.0  # gamma_7
    beta: float = 1.0
    fk_unit: float = 0.1  # metres per loss unit (decimetres)
    fk_beta: float = 1.0  # in fk_unit, i.e. 10 cm
    constraint: float = 10.0  # kinema addition, see motion_loss: reproduce imputed constraints
    constraint_beta: float = 0.05  # in feature standard deviations (about 9 cm of smoothed root)
    foot_contact: float = 0.0  # kinema addition (MDM's foot loss), see motion_loss; 0 = Eq. 1 only
    foot_unit: float = 0.1  # metres per second per loss unit of the foot-contact term

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> LossWeights:
        return cls(**{k: float(v) for k, v in d.items()})


def _masked_mean(elementwise: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of ``elementwise (B, T, ...)`` over valid frames (``mask (B, T)``) and all channels."""
    per_frame = elementwise.flatten(2)
    per_frame = torch.where(mask[..., None], per_frame, torch.zeros_like(per_frame))
    count = mask.sum().clamp_min(1) * per_frame.shape[-1]
    return per_frame.sum() / count


def foot_contact_term(
    pred_m: torch.Tensor,
    target_m: torch.Tensor,
    mask: torch.Tensor,
    layout: FeatureLayout,
    skeleton: Skeleton,
    fps: float,
    weights: LossWeights,
) -> torch.Tensor:
    """Foot-contact consistency (MDM's foot loss) on *unnormalised* features ``(B, T, D)``.

    The predicted motion is rebuilt as the sampler's output is (features_to_motion: pelvis at the
    predicted smoothed root + its ``j_p``, other joints by FK of the predicted global rotations); the
    velocities (m/s, forward differences) of the four contact joints are pushed towards zero on frames
    where the *ground-truth* contact flag of that joint is 1 and both frames are valid. Smooth L1 in
    units of ``weights.foot_unit`` m/s (beta 1 unit), mean over the contact entries of the batch.
    Why: Eq. 1 never asks the feet the model moves by FK to stay where the contact channels say they
    are planted, and the raw output slides its planted feet (issue 18).
    """
    parts = layout.split(pred_m)
    root = parts["joint_pos"][..., 0, :] + torch.stack(
        [parts["root_pos"][..., 0], torch.zeros_like(parts["root_pos"][..., 1]), parts["root_pos"][..., 2]], dim=-1
    )
    feet = positions_from_sixd(parts["joint_rot"], root, skeleton)[..., contact_joints(skeleton), :]
    vel = (feet[:, 1:] - feet[:, :-1]) * fps / weights.foot_unit  # (B, T-1, 4, 3)
    planted = layout.split(target_m)["contacts"][:, :-1] > 0.5  # (B, T-1, 4)
    use = planted & (mask[:, 1:] & mask[:, :-1])[..., None]
    err = F.smooth_l1_loss(vel, torch.zeros_like(vel), reduction="none", beta=1.0).sum(-1)
    err = torch.where(use, err, torch.zeros_like(err))
    return err.sum() / use.sum().clamp_min(1)


def motion_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    pad_mask: torch.Tensor,
    layout: FeatureLayout,
    skeleton: Skeleton,
    stats: NormStats,
    weights: LossWeights = LossWeights(),
    constraint_mask: torch.Tensor | None = None,
    fps: float | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Eq. 1: ``(total, {term: unweighted value})`` for normalised ``pred``/``target`` ``(B, T, D)``.

    ``total = sum_i gamma_i * term_i`` is a differentiable scalar; the dict holds each of the seven
    terms (keys of :data:`TERMS`) as detached 0-d tensors, for logging. ``pad_mask (B, T)`` is True on
    valid frames.

    FK term: ``pred`` is unnormalised with ``stats``, its global 6D rotations become matrices and FK
    (:func:`kinema.kinematics.positions_from_global_rotations`) places the root joint at the *target*
    root joint position (x/z relative to the target smoothed root, y global, i.e. the target ``j_p``
    of joint 0). The predicted root/translation therefore plays no part: the term measures only how well
    the predicted rotations reproduce the target joint positions (translation errors are already the
    business of the root_pos and joint_pos terms). The comparison is in metres, divided by
    ``weights.fk_unit`` (see :class:`LossWeights`); FK runs in float32 even under autocast.

    Constraint term (not in the paper): with ``constraint_mask (B, T, D)`` (the {0, 1} imputation mask
    of phase 2) the dict gains ``"constraint"``, a smooth L1 with the small ``weights.constraint_beta``
    over the constrained entries only, added with weight ``weights.constraint``. Eq. 1 weighs an
    imputed entry like any other and, with beta = 1 std, barely pulls on errors below one standard
    deviation (1.9 m for the smoothed root), so a CPU-sized run left 30 cm between its output and the
    waypoints it was given; this term teaches the model to reproduce what it was told.

    Foot-contact term (not in the paper): with ``weights.foot_contact > 0`` the dict gains
    ``"foot_contact"`` (:func:`foot_contact_term`), added with that weight; it needs ``fps``.
    """
    _check_shapes(pred, target, pad_mask, layout, skeleton)
    mask = pad_mask.to(device=pred.device, dtype=torch.bool)
    # Zero padded frames first: garbage (even NaN) there cannot leak into values or gradients.
    keep = mask[..., None]
    pred = torch.where(keep, pred, torch.zeros_like(pred))
    target = torch.where(keep, target, torch.zeros_like(target))

    terms: dict[str, torch.Tensor] = {}
    for name, sl in layout.slices.items():
        err = F.smooth_l1_loss(pred[..., sl], target[..., sl], reduction="none", beta=weights.beta)
        terms[name] = _masked_mean(err, mask)
    terms.update(_metre_terms(pred, target, mask, layout, skeleton, stats, weights, fps))

    total = sum(getattr(weights, name) * terms[name] for name in TERMS)
    if "foot_contact" in terms:
        total = total + weights.foot_contact * terms["foot_contact"]
    logged = {name: term.detach() for name, term in terms.items()}
    if constraint_mask is not None:
        term = _constraint_term(pred, target, keep, constraint_mask, weights)
        total = total + weights.constraint * term
        logged["constraint"] = term.detach()
    return total, logged


def _check_shapes(
    pred: torch.Tensor, target: torch.Tensor, pad_mask: torch.Tensor, layout: FeatureLayout, skeleton: Skeleton
) -> None:
    """Reject mismatched inputs with a message naming the shapes, before any arithmetic broadcasts them."""
    if pred.shape != target.shape or pred.ndim != 3 or pred.shape[-1] != layout.dim:
        raise ValueError(f"pred {tuple(pred.shape)} and target {tuple(target.shape)} must both be (B, T, {layout.dim})")
    if pad_mask.shape != pred.shape[:2]:
        raise ValueError(f"pad_mask has shape {tuple(pad_mask.shape)}, expected {tuple(pred.shape[:2])}")
    if skeleton.num_joints != layout.num_joints:
        raise ValueError(f"skeleton has {skeleton.num_joints} joints, layout {layout.num_joints}")


def _metre_terms(
    pred: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor,
    layout: FeatureLayout,
    skeleton: Skeleton,
    stats: NormStats,
    weights: LossWeights,
    fps: float | None,
) -> dict[str, torch.Tensor]:
    """The terms computed on denormalised features (``"fk"``, and ``"foot_contact"`` when weighted),
    in float32 with autocast off so that FK keeps its precision under mixed precision."""
    terms: dict[str, torch.Tensor] = {}
    with torch.autocast(device_type=pred.device.type, enabled=False):
        pred_m = stats.denormalize(pred.float())
        target_m = stats.denormalize(target.float())
        rot6 = layout.split(pred_m)["joint_rot"]  # (B, T, J, 6)
        target_jp = layout.split(target_m)["joint_pos"]  # (B, T, J, 3)
        # Placing the root joint at its j_p entry (x/z relative to the smoothed root, y global) yields
        # every joint directly in the j_p representation, since FK is translation-equivariant.
        fk_jp = positions_from_sixd(rot6, target_jp[..., 0, :], skeleton)
        err = F.smooth_l1_loss(
            fk_jp / weights.fk_unit, target_jp / weights.fk_unit, reduction="none", beta=weights.fk_beta
        )
        terms["fk"] = _masked_mean(err, mask)
        if weights.foot_contact > 0:
            if fps is None or not fps > 0:
                raise ValueError(f"the foot-contact term needs the motion's fps, got {fps}")
            terms["foot_contact"] = foot_contact_term(pred_m, target_m, mask, layout, skeleton, fps, weights)
    return terms


def _constraint_term(
    pred: torch.Tensor, target: torch.Tensor, keep: torch.Tensor, constraint_mask: torch.Tensor, weights: LossWeights
) -> torch.Tensor:
    """Smooth L1 with the small ``constraint_beta`` averaged over the constrained, valid entries only."""
    if constraint_mask.shape != pred.shape:
        raise ValueError(f"constraint_mask has shape {tuple(constraint_mask.shape)}, expected {tuple(pred.shape)}")
    m = torch.where(keep, constraint_mask.to(pred.dtype), torch.zeros_like(pred))
    err = F.smooth_l1_loss(pred, target, reduction="none", beta=weights.constraint_beta)
    return (err * m).sum() / m.sum().clamp_min(1.0)
