"""Render markers for a constraints file's objectives (``kinema render --constraints``).

Objectives have no frame, so their markers show on every panel (kinema.render targets with frame None):
a reach target as a labelled point, a time-agnostic path as points every ~10 cm along it (on the floor
for a ground path), the centres of spheres to avoid. Joint distances and bounds have nothing to mark.
"""

from __future__ import annotations

import torch

from kinema.objectives.io import load_objectives
from kinema.objectives.path import PathTimeAgnostic
from kinema.objectives.snap import point_at_fraction
from kinema.objectives.terms import Avoid, Reach

PATH_SPACING = 0.1  # metres between path markers


def objective_targets(path) -> list[tuple]:
    """``(None, position, label)`` markers for the objectives in the constraints file ``path``."""
    out: list[tuple] = []
    for o in load_objectives(path):
        if isinstance(o, Reach):
            out.append((None, list(o.target), f"reach {o.joint}"))
        elif isinstance(o, PathTimeAgnostic):
            pts = torch.tensor(o.path, dtype=torch.float64)
            length = float((pts[1:] - pts[:-1]).norm(dim=-1).sum())
            n = max(2, int(length / PATH_SPACING) + 1)
            out += [(None, p.tolist(), "") for p in point_at_fraction(pts, torch.linspace(0, 1, n, dtype=pts.dtype))]
        elif isinstance(o, Avoid):
            out += [(None, list(c), "avoid") for c, _ in o.spheres]
    return out
