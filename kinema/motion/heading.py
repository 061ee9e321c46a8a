"""Facing direction of a pose: the heading ``(cos psi, sin psi)`` from the hips (psi about +Y, 0 = +Z).

Shapes: positions ``(..., T, J, 3)`` metres, Y up -> heading ``(..., T, 2)``.
"""

from __future__ import annotations

import torch

from kinema.skeleton import Skeleton


def heading_from_positions(positions: torch.Tensor, skeleton: Skeleton) -> torch.Tensor:
    """Heading ``(cos psi, sin psi)`` (..., T, 2) from global positions (..., T, J, 3)."""
    roles = skeleton.require_roles(["left_hip", "right_hip"])
    v = positions[..., roles["right_hip"], :] - positions[..., roles["left_hip"], :]
    # e_y x v = (v_z, 0, -v_x); psi measured from +Z towards +X
    fx, fz = v[..., 2], -v[..., 0]
    norm = torch.sqrt(fx**2 + fz**2).clamp_min(1e-9)
    return torch.stack([fz / norm, fx / norm], dim=-1)
