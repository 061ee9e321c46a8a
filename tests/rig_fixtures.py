"""Synthetic skeletons for rig / representation / post-processing tests (Y up, +Z forward, metres).

- ``human()``: the shipped model's 21-joint Bandai Namco skeleton (read from its checkpoint.json);
- ``hexapod()``: an insect, a body chain of 3 segments with a 3-joint leg on each side of each (6 legs);
- ``quadruped()``: spine + neck/head + tail, 4 legs of hip/knee/ankle/toe joints with creature names;
- ``fish()``: a horizontal body with fins and a 3-joint tail (no legs);
- ``snake2()``: two joints in a line (the smallest rig);
- ``walking(skeleton)``: a motion on any of them whose feet skate.
"""

from __future__ import annotations

import json
from importlib.resources import files

import torch

from kinema.geometry.rotations import axis_angle_to_quat
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton


def human() -> Skeleton:
    ckpt = json.loads((files("kinema") / "assets" / "models" / "default" / "checkpoint.json").read_text())
    return Skeleton.from_dict(ckpt["skeleton"])


def _build(rows: list[tuple[str, str | None, tuple[float, float, float]]], name: str) -> Skeleton:
    names = [r[0] for r in rows]
    parents = [-1 if r[1] is None else names.index(r[1]) for r in rows]
    return Skeleton(names, parents, torch.tensor([r[2] for r in rows], dtype=torch.float64), name=name)


def hexapod() -> Skeleton:
    rows = [("Thorax", None, (0.0, 0.12, 0.0))]
    for k in range(2):  # two more body segments behind the thorax
        rows.append((f"Seg{k + 1}", "Thorax" if k == 0 else f"Seg{k}", (0.0, 0.0, -0.06)))
    bodies = ["Thorax", "Seg1", "Seg2"]
    for i, body in enumerate(bodies):
        for side, x in (("A", 1.0), ("B", -1.0)):
            leg = f"Leg{i}{side}"
            rows += [
                (f"{leg}_1", body, (0.03 * x, 0.0, 0.0)),
                (f"{leg}_2", f"{leg}_1", (0.05 * x, 0.02, 0.0)),
                (f"{leg}_3", f"{leg}_2", (0.04 * x, -0.13, 0.0)),
            ]
    return _build(rows, "hexapod")


def quadruped() -> Skeleton:
    rows = [
        ("Body", None, (0.0, 0.6, 0.0)),
        ("Chest", "Body", (0.0, 0.0, 0.35)),
        ("NeckA", "Chest", (0.0, 0.15, 0.1)),
        ("HeadA", "NeckA", (0.0, 0.1, 0.1)),
        ("TailA", "Body", (0.0, 0.05, -0.35)),
        ("TailB", "TailA", (0.0, 0.0, -0.2)),
    ]
    for where, parent, z in (("Front", "Chest", 0.0), ("Back", "Body", -0.3)):
        for side, x in (("A", 0.12), ("B", -0.12)):
            leg = f"{where}{side}"
            rows += [
                (f"{leg}1", parent, (x, -0.05, z)),
                (f"{leg}2", f"{leg}1", (0.0, -0.25, 0.03)),
                (f"{leg}3", f"{leg}2", (0.0, -0.25, -0.03)),
                (f"{leg}4", f"{leg}3", (0.0, -0.04, 0.06)),
            ]
    return _build(rows, "quadruped")


def fish() -> Skeleton:
    rows = [
        ("Body", None, (0.0, 0.5, 0.0)),
        ("Head", "Body", (0.0, 0.0, 0.3)),
        ("Fin_L", "Body", (0.1, -0.05, 0.1)),
        ("Fin_R", "Body", (-0.1, -0.05, 0.1)),
        ("Tail_1", "Body", (0.0, 0.0, -0.2)),
        ("Tail_2", "Tail_1", (0.0, 0.0, -0.2)),
        ("Tail_3", "Tail_2", (0.0, 0.0, -0.2)),
    ]
    return _build(rows, "fish")


def walking(skeleton: Skeleton, frames: int = 30, speed: float = 0.1, fps: float = 20.0) -> Motion:
    """The rest pose gliding forward (+Z) at ``speed`` m/s with a small sway in every joint: every
    foot skates at about ``speed``."""
    t = torch.arange(frames, dtype=torch.float64) / fps
    J = skeleton.num_joints
    aa = torch.zeros(frames, J, 3, dtype=torch.float64)
    aa[..., 0] = 0.05 * torch.sin(2 * torch.pi * t)[:, None] * torch.linspace(-1, 1, J)
    root = skeleton.offsets[0].expand(frames, 3).clone()
    root[:, 2] += speed * t
    return Motion(skeleton, fps, root, axis_angle_to_quat(aa))


def snake2() -> Skeleton:
    return _build([("A", None, (0.0, 0.05, 0.0)), ("B", "A", (0.0, 0.0, -0.5))], "snake2")
