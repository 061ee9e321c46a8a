"""Random constraint masks for training the any-rig model (the imputation path of generation).

``random_masks(frame_mask, channel_mask, gen, p_constrained)`` returns a {0, 1} float mask
``(B, T, J, C)``: per sample, with probability ``1 - p_constrained`` nothing; otherwise one of
full-body keyframes (1-3 frames), joint positions (1-3 non-root joints at 1-4 frames), a prefix
of 1..T/2 full frames (what window blending imputes from the previous window), or the root row on
every frame (a given root trajectory). Only real frames and channels are ever constrained.
"""

from __future__ import annotations

import torch

from kinema.representation.joint import POS

KINDS = ("keyframes", "joints", "prefix", "root")


def _pick(n: int, k: int, gen: torch.Generator) -> torch.Tensor:
    return torch.randperm(n, generator=gen)[: min(k, n)]


def _one(mask, frames, J, root, gen):
    kind = KINDS[int(torch.randint(len(KINDS), (1,), generator=gen))]
    if kind == "keyframes":
        mask[_pick(frames, int(torch.randint(1, 4, (1,), generator=gen)), gen)] = 1.0
    elif kind == "joints":
        others = [j for j in range(J) if j != root] or [root]
        js = torch.tensor(others)[_pick(len(others), int(torch.randint(1, 4, (1,), generator=gen)), gen)]
        fs = _pick(frames, int(torch.randint(1, 5, (1,), generator=gen)), gen)
        mask[fs[:, None], js[None, :], POS] = 1.0
    elif kind == "prefix":
        mask[: int(torch.randint(1, max(2, frames // 2 + 1), (1,), generator=gen))] = 1.0
    else:
        mask[:frames, root] = 1.0


def random_masks(
    frame_mask: torch.Tensor,
    channel_mask: torch.Tensor,
    root_flag: torch.Tensor,
    gen: torch.Generator,
    p_constrained: float = 0.5,
) -> torch.Tensor:
    """See the module docstring. ``frame_mask (B, T)``, ``channel_mask (B, J, C)``, ``root_flag (B, J)``."""
    B, T = frame_mask.shape
    J, C = channel_mask.shape[1:]
    out = torch.zeros(B, T, J, C)
    for b in range(B):
        if float(torch.rand(1, generator=gen)) >= p_constrained:
            continue
        frames = int(frame_mask[b].sum())
        joints = int(channel_mask[b].any(-1).sum())
        _one(out[b], frames, joints, int(root_flag[b].argmax()), gen)
    return out * frame_mask[:, :, None, None] * channel_mask[:, None]
