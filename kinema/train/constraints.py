"""Phase-2 training-time sampling of constraint masks (the builders live in kinema.representation.masks).

Kimodo conditions on constraints by imputation (paper Sec. 4.2): a target motion ``x_tgt`` and a binary
mask ``m`` over feature channels, ``x~_t = m * x_tgt + (1 - m) * x_t``. During training phase 2
(Sec. 4.3, "Training Curriculum") the target is the ground truth itself (``x_tgt = x0``), so only the
mask is sampled here. All masks are ``(T, D)`` float in {0, 1} over the FeatureLayout channels
``[root_pos 3, heading 2, joint_pos 3J, joint_vel 3J, joint_rot 6J, contacts 4]``.

Patterns and exactly the channels they set (at the chosen frames only):

- ``fullbody``: K sparse keyframes; root_pos (x, y, z), heading (2), joint_pos and joint_rot of every
  joint. Not joint_vel, not contacts.
- ``end_effector``: K sparse keyframes; a uniformly random non-empty subset of the effectors
  {left_hand, right_hand, left_foot, right_foot} (a foot is its ankle and toe joints, a hand its hand
  joint, found via skeleton roles), each constrained by position (joint_pos), rotation (joint_rot) or
  both (uniformly), plus root_pos x and z. joint_pos x/z are relative to the smoothed root, so a
  *global* position target needs the root x/z at those frames (as Kimodo's constraint files carry
  ``smooth_root_2d``).
- ``root2d``: K sparse keyframes; root_pos x and z, plus heading with probability 0.5.
- ``root_path``: one dense interval of random length in [ceil(T/4), T] frames at a uniform random start;
  root_pos x and z, plus heading with probability 0.5.
- ``contacts``: K sparse keyframes; the 4 contact channels.

Mixing (paper): 10% of samples have no constraint, 25% the union of two distinct patterns, the other
65% one pattern. Patterns are drawn with ``pattern_probs`` (default uniform over those the skeleton
supports). The number of keyframes K follows a truncated geometric law biased to few keyframes:
``P(K = k) = q^(k-1) (1 - q) / (1 - q^Kmax)`` for ``k = 1..Kmax`` (``q = keyframe_decay``, 0.8 by
default: mean about 4 when Kmax = 20), then ``K = min(K, T)``; keyframes are K distinct frames drawn
uniformly. Every random draw comes from the given ``torch.Generator`` in a fixed order, so sampling is
reproducible.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import torch

from kinema.errors import KinemaError
from kinema.representation.layout import FeatureLayout
from kinema.representation.masks import (
    EFFECTORS,
    contacts_mask,
    effector_joints,
    end_effector_mask,
    fullbody_mask,
    root2d_mask,
    root_path_mask,
)
from kinema.skeleton import Skeleton

PATTERNS = ("fullbody", "end_effector", "root2d", "root_path", "contacts")
P_NONE = 0.10
P_PAIR = 0.25
KEYFRAME_DECAY = 0.8

__all__ = ["EFFECTORS", "PATTERNS", "contacts_mask", "effector_joints", "end_effector_mask", "fullbody_mask",
           "max_keyframes_at", "root2d_mask", "root_path_mask", "sample_batch_masks", "sample_constraint_mask",
           "sample_num_keyframes"]


# ---------------------------------------------------------------------------- sampling
def _uniform(g: torch.Generator) -> float:
    return float(torch.rand((), generator=g))


def _randint(lo: int, hi: int, g: torch.Generator) -> int:
    """Uniform integer in [lo, hi] (inclusive)."""
    return int(torch.randint(lo, hi + 1, (), generator=g))


def sample_num_keyframes(max_keyframes: int, g: torch.Generator, decay: float = KEYFRAME_DECAY) -> int:
    """K in [1, max_keyframes] with ``P(K = k)`` proportional to ``decay^(k-1)`` (inverse CDF)."""
    if not 0.0 < decay < 1.0:
        raise ValueError(f"keyframe decay must be in (0, 1), got {decay}")
    kmax = max(int(max_keyframes), 1)
    u = _uniform(g)
    k = 1 + math.floor(math.log1p(-u * (1.0 - decay**kmax)) / math.log(decay))
    return min(max(k, 1), kmax)


def _keyframes(T: int, max_keyframes: int, g: torch.Generator, decay: float) -> torch.Tensor:
    k = min(sample_num_keyframes(max_keyframes, g, decay), T)
    return torch.randperm(T, generator=g)[:k].sort().values


def _sample_pattern(
    name: str,
    T: int,
    layout: FeatureLayout,
    skeleton: Skeleton,
    max_keyframes: int,
    g: torch.Generator,
    decay: float,
    effectors: Sequence[str],
) -> torch.Tensor:
    if name == "root_path":
        length = _randint(math.ceil(0.25 * T), T, g)
        start = _randint(0, T - length, g)
        return root_path_mask(T, start, start + length, layout, heading=_uniform(g) < 0.5)
    frames = _keyframes(T, max_keyframes, g, decay)
    if name == "fullbody":
        return fullbody_mask(T, frames, layout)
    if name == "root2d":
        return root2d_mask(T, frames, layout, heading=_uniform(g) < 0.5)
    if name == "contacts":
        return contacts_mask(T, frames, layout)
    if name == "end_effector":
        subset = _randint(1, 2 ** len(effectors) - 1, g)  # uniform over non-empty subsets
        pos, rot = [], []
        for i, eff in enumerate(effectors):
            if subset >> i & 1:
                mode = _randint(0, 2, g)  # 0 position, 1 rotation, 2 both
                if mode != 1:
                    pos.append(eff)
                if mode != 0:
                    rot.append(eff)
        return end_effector_mask(T, frames, layout, skeleton, pos, rot)
    raise KinemaError(f"unknown constraint pattern {name!r}; choose from {list(PATTERNS)}")


def _pattern_weights(pattern_probs: Mapping[str, float] | None, effectors: Sequence[str]) -> torch.Tensor:
    probs = dict.fromkeys(PATTERNS, 1.0) if pattern_probs is None else dict(pattern_probs)
    unknown = set(probs) - set(PATTERNS)
    if unknown:
        raise KinemaError(f"unknown constraint patterns {sorted(unknown)}; choose from {list(PATTERNS)}")
    if not effectors:
        probs["end_effector"] = 0.0  # the skeleton has no hand/foot roles
    w = torch.tensor([float(probs.get(p, 0.0)) for p in PATTERNS], dtype=torch.float64)
    if (w < 0).any() or not torch.isfinite(w).all() or w.sum() <= 0:
        raise KinemaError(f"pattern probabilities must be non-negative with a positive sum, got {probs}")
    return w


def sample_constraint_mask(
    features: torch.Tensor,
    layout: FeatureLayout,
    skeleton: Skeleton,
    max_keyframes: int,
    generator: torch.Generator,
    pattern_probs: Mapping[str, float] | None = None,
    *,
    p_none: float = P_NONE,
    p_pair: float = P_PAIR,
    keyframe_decay: float = KEYFRAME_DECAY,
) -> torch.Tensor:
    """A phase-2 training mask ``(T, D)`` (float {0, 1}, dtype/device of ``features``) for one clip.

    ``features (T, D)`` is the unnormalised ground truth; it is also the constraint target, so only its
    length is used here. See the module docstring for patterns, mixing and the keyframe-count law.
    """
    if features.ndim != 2 or features.shape[-1] != layout.dim:
        raise ValueError(f"features must be (T, {layout.dim}), got {tuple(features.shape)}")
    T = features.shape[0]
    dtype = features.dtype if features.is_floating_point() else torch.float32
    mask = torch.zeros(T, layout.dim)
    effectors = [e for e in EFFECTORS if effector_joints(skeleton, e)]
    w = _pattern_weights(pattern_probs, effectors)
    u = _uniform(generator)
    if T == 0 or u < p_none:
        return mask.to(dtype=dtype, device=features.device)
    count = 2 if (u < p_none + p_pair and int((w > 0).sum()) >= 2) else 1
    chosen = torch.multinomial(w, count, replacement=False, generator=generator).tolist()
    for i in chosen:
        part = _sample_pattern(
            PATTERNS[i], T, layout, skeleton, max_keyframes, generator, keyframe_decay, effectors
        )
        mask = torch.maximum(mask, part)
    return mask.to(dtype=dtype, device=features.device)


def sample_batch_masks(
    features: torch.Tensor,
    lengths: torch.Tensor | Sequence[int],
    layout: FeatureLayout,
    skeleton: Skeleton,
    max_keyframes: int,
    generator: torch.Generator,
    pattern_probs: Mapping[str, float] | None = None,
    **kwargs,
) -> torch.Tensor:
    """Masks ``(B, T, D)`` for padded ``features (B, T, D)``: item i is sampled on its first
    ``lengths[i]`` frames (as :func:`sample_constraint_mask`, same keyword options); padding stays 0."""
    if features.ndim != 3:
        raise ValueError(f"features must be (B, T, D), got {tuple(features.shape)}")
    B, T, _ = features.shape
    lengths = [int(n) for n in torch.as_tensor(lengths).reshape(-1).tolist()]
    if len(lengths) != B or any(not 0 <= n <= T for n in lengths):
        raise ValueError(f"lengths {lengths} do not fit a batch of {B} clips of {T} frames")
    dtype = features.dtype if features.is_floating_point() else torch.float32
    out = torch.zeros(B, T, layout.dim, dtype=dtype, device=features.device)
    for i, n in enumerate(lengths):
        out[i, :n] = sample_constraint_mask(
            features[i, :n], layout, skeleton, max_keyframes, generator, pattern_probs, **kwargs
        )
    return out


def max_keyframes_at(step: int, phase2_start: int, phase2_steps: int, start: int = 1, end: int = 20) -> int:
    """Keyframe cap at training ``step``: ``start`` until phase 2 begins, then a linear ramp to ``end``.

    ``floor(start + (end - start + 1) * progress)`` clamped to ``end``, with ``progress`` the fraction
    of phase 2 done (in [0, 1]): each value from ``start`` to ``end`` holds for an equal share of phase 2
    (with the defaults: 1 at its start, 11 half way, 20 over its last twentieth and after).
    """
    if phase2_steps <= 0:
        return end if step >= phase2_start else start
    progress = min(max((step - phase2_start) / phase2_steps, 0.0), 1.0)
    return min(start + math.floor((end - start + 1) * progress), end)
