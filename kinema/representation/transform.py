"""Rigid ground-plane transforms applied directly to Kimodo features (training augmentation).

Turning a motion about +Y by ``angle`` and shifting it on the ground only rotates the x/z parts of the
vector-valued groups, adds ``angle`` to the heading and left-multiplies the global rotations; contacts
and heights are unchanged. Working on features avoids a features -> motion -> features round trip per
training sample. Shapes: features ``(..., T, D)``; angles ``(...)`` radians; offsets ``(..., 2)`` metres.
"""

from __future__ import annotations

import torch

from kinema.representation.layout import FeatureLayout


def _rotate_xz(v: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """Rotate (..., 3) vectors about +Y; c, s broadcast against v[..., 0]."""
    x, y, z = v.unbind(-1)
    return torch.stack([c * x + s * z, y, -s * x + c * z], dim=-1)


def rotate_features(features: torch.Tensor, angle: torch.Tensor, layout: FeatureLayout) -> torch.Tensor:
    """Features of the motion turned by ``angle`` (..., ) radians about the world +Y axis (through 0)."""
    angle = torch.as_tensor(angle, dtype=features.dtype, device=features.device)
    c = torch.cos(angle)[..., None]  # (..., 1) broadcast over T
    s = torch.sin(angle)[..., None]
    p = layout.split(features)
    root = _rotate_xz(p["root_pos"], c, s)
    hc, hs = p["heading"].unbind(-1)
    heading = torch.stack([hc * c - hs * s, hs * c + hc * s], dim=-1)  # psi + angle
    cj, sj = c[..., None], s[..., None]  # (..., 1, 1) broadcast over T and J
    jp = _rotate_xz(p["joint_pos"], cj, sj)
    jv = _rotate_xz(p["joint_vel"], cj, sj)
    rot = p["joint_rot"]
    col0 = _rotate_xz(rot[..., :3], cj, sj)
    col1 = _rotate_xz(rot[..., 3:], cj, sj)
    return torch.cat(
        [root, heading, jp.flatten(-2), jv.flatten(-2), torch.cat([col0, col1], -1).flatten(-2), p["contacts"]],
        dim=-1,
    )


def translate_features(features: torch.Tensor, offset_xz: torch.Tensor, layout: FeatureLayout) -> torch.Tensor:
    """Features of the motion shifted by ``offset_xz`` (..., 2) metres on the ground.

    Only the smoothed root moves: joint positions are stored relative to it."""
    out = features.clone()
    x, z = layout.root_xz
    out[..., x] = out[..., x] + offset_xz[..., 0:1]
    out[..., z] = out[..., z] + offset_xz[..., 1:2]
    return out


def canonicalize_start(features: torch.Tensor, layout: FeatureLayout, angle=None) -> torch.Tensor:
    """Move the first frame's root over the origin and, when ``angle`` is given, set its heading to it.

    This is the Kimodo training normalisation: first-frame root above the origin, random first-frame
    heading (the model learns to follow ``c_dir`` rather than a canonical facing)."""
    sl = layout.slices
    start = features[..., 0, layout.root_xz]
    out = translate_features(features, -start, layout)
    if angle is not None:
        hc, hs = features[..., 0, sl["heading"]].unbind(-1)
        current = torch.atan2(hs, hc)
        out = rotate_features(out, torch.as_tensor(angle, dtype=features.dtype) - current, layout)
    return out
