"""The root's heading of a sampled any-rig motion read from the model's heading *rate*, not its per-frame
cos/sin (issue 34: "walks forward" turning on the spot).

The root row carries both the heading's cosine and sine and its rate (rad/s,
kinema.representation.joint). Training turns every window to a random heading, so the cos/sin pair says
little frame to frame: sampled by the small CPU model it jitters by tens of degrees between frames (a
4-s walk of the 1 500-step fine-tune: 1 260-1 440 deg of summed turning on three held-out rigs, where the
rate channel of the same sample sums to 67-180 deg and nets 6-66 deg), and the motion, posed from it,
spins. `heading_from_rate` keeps the model's own rate for how the heading changes (integrated from frame
0) and the cos/sin only for where it points overall: the integrated path is turned by the circular mean
of its difference from the cos/sin heading. Both are the model's predictions; nothing is added.

Used for a single prompt when no constraint fixes the heading (a root path, a keyframe or a copied root
motion set cos/sin at their frames). Timelines keep the cos/sin as sampled: at a join between two
prompts the model turns the body's rotations (relative to the heading) together with its cos/sin, and
reading the heading from the rate there tore the join (a synthetic dog's walk -> death: a 0.58 m step
against 0.10 elsewhere). Shapes: ``(S, T, J, C)`` features.
"""

from __future__ import annotations

import torch

from kinema.representation.joint import ROOT_HEADING_COS, ROOT_HEADING_RATE, ROOT_HEADING_SIN


def heading_from_rate(feats: torch.Tensor, root: int, fps: float) -> torch.Tensor:
    """``feats (S, T, J, C)`` with the root's cos/sin replaced by the heading integrated from its rate,
    turned to agree on average with the sampled cos/sin (see the module)."""
    out = feats.clone()
    f = out[:, :, root].to(torch.float64)
    psi_cs = torch.atan2(f[..., ROOT_HEADING_SIN], f[..., ROOT_HEADING_COS])  # (S, T)
    rate = f[..., ROOT_HEADING_RATE]
    psi = torch.zeros_like(psi_cs)
    psi[:, 1:] = torch.cumsum(rate[:, :-1], dim=1) / fps  # the rate at t is (psi[t+1] - psi[t]) * fps
    off = psi_cs - psi
    psi = psi + torch.atan2(torch.sin(off).mean(1, keepdim=True), torch.cos(off).mean(1, keepdim=True))
    out[:, :, root, ROOT_HEADING_COS] = torch.cos(psi).to(out.dtype)
    out[:, :, root, ROOT_HEADING_SIN] = torch.sin(psi).to(out.dtype)
    return out
