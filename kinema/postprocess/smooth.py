"""Remove frame-to-frame jitter from a generated motion (the first post-processing stage).

A diffusion model's x0 prediction carries a little independent noise on every frame; on a small,
CPU-trained model it shows as a pelvis that shivers by a few centimetres between frames (measured on
the 4000-step checkpoint of the shipped model's run, a 4-s walk: second differences of joint
positions 36x those of the data; 12x after smoothing the root's x/z alone, because the pelvis comes
from the root stage's global smoothed-root estimate, the least precise output). The default therefore
filters the ground-plane (x, z) root translation only (Gaussian, ``sigma_root`` = 0.05 s, one frame at
20 fps): on clean Bandai Namco captures that moves no joint of a walk by more than 0.7 cm, of a run
1.5 cm, of a dash 1.0 cm and of a spinning kick 2.2 cm; the vertical bounce is left alone.
Rotations are filtered too (``sigma_rot``; quaternions made sign-continuous over time, smoothed,
re-normalised). ``smooth_motion`` leaves them alone unless asked; ``postprocess`` asks for
``DEFAULT_ROT_SIGMA_SECONDS`` = 0.04 s because the shipped model's limbs shake: on a generated 4-s
walk, hand and foot jerk relative to the pelvis is 14x and 9x that of a captured walk (spine 1.7x).
Measured with ``sigma_rot`` 0 / 0.03 / 0.04 / 0.05 s: generated walk jerk 908 / 465 / 309 / 260 m/s^3
(run 1876 / 1117 / 874 / 808); on 40 clean test captures the mean joint displacement is 0 / 0.13 /
0.22 / 0.32 cm and the 95th percentile of the per-clip largest displacement 0 / 3.0 / 5.2 / 7.5 cm
(fast kicks and arm swings lose a little of their peak). 0.04 s trades most of the shake for a
blur of fast peaks that stays under the model's own errors.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time

DEFAULT_SIGMA_SECONDS = 0.05  # root x/z translation
DEFAULT_ROT_SIGMA_SECONDS = 0.04  # local rotations, as post-processing applies them


def continuous_quaternions(q: torch.Tensor) -> torch.Tensor:
    """Flip signs of ``q (T, J, 4)`` so each frame is in the hemisphere of the previous one (same rotations).

    Frame t's sign is the product of the flips between consecutive input frames up to t (a flip of
    frame t - 1 flips its dot product with frame t too), so one cumulative product does it."""
    if q.shape[0] < 2:
        return q.clone()
    flips = torch.where((q[1:] * q[:-1]).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(q.dtype)
    sign = torch.cat([torch.ones_like(flips[:1]), torch.cumprod(flips, dim=0)])
    return q * sign


def smooth_motion(
    motion: Motion, sigma_root: float = DEFAULT_SIGMA_SECONDS, sigma_rot: float = 0.0
) -> tuple[Motion, dict]:
    """Gaussian-smooth the root translation (and, if ``sigma_rot`` > 0, local rotations); sigmas in seconds.

    Returns the motion and a report with the largest joint displacement the filter made (cm) and the
    mean second difference of joint positions before and after (cm / frame^2). Zero sigmas are a no-op.
    """
    root_frames, rot_frames = float(sigma_root) * motion.fps, float(sigma_rot) * motion.fps
    report = {"sigma_root_s": float(sigma_root), "sigma_rot_s": float(sigma_rot), "max_shift_cm": 0.0}
    if (root_frames <= 0 and rot_frames <= 0) or motion.num_frames < 3:
        return motion, report
    q = motion.local_rotations
    if rot_frames > 0:
        T, J = q.shape[:2]
        q = smooth_time(continuous_quaternions(q).reshape(T, J * 4), rot_frames).reshape(T, J, 4)
        q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    root = motion.root_translation
    if root_frames > 0:  # ground-plane x/z only: the vertical bounce of a run or jump is real detail
        root = root.clone()
        root[:, [0, 2]] = smooth_time(root[:, [0, 2]], root_frames)
    out = replace(motion, root_translation=root, local_rotations=q)
    before, after = motion.positions, out.positions
    report.update({
        "max_shift_cm": float(100 * (after - before).norm(dim=-1).max()),
        "accel_before_cm": float(100 * _accel(before)),
        "accel_after_cm": float(100 * _accel(after)),
    })
    return out, report


def _accel(p: torch.Tensor) -> torch.Tensor:
    return (p[2:] - 2 * p[1:-1] + p[:-2]).norm(dim=-1).mean()
