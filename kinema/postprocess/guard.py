"""The guard: post-processing never makes a motion less plausible than the raw one without saying so.

Every post-processing stage (de-jittering, foot locking, exact constraint hitting) edits a motion the
model already made plausible. A stage that goes wrong -- an ill-posed constraint, a target 50 m away,
a foot lock fighting a constraint -- can throw the pelvis metres per frame while still reporting small
residuals. So after each stage the motion's plausibility is compared with the *raw* motion's and the
stage is undone (the motion before it is kept) when it exceeds a documented bound; the reason goes
into the report's ``warnings`` (and the CLI prints it on stderr).

Plausibility (``plausibility``), from global joint positions ``(T, J, 3)`` in metres:
- ``pelvis_speed`` (m/s): the largest frame-to-frame speed of the pelvis;
- ``added_pelvis_speed`` (m/s): the largest frame-to-frame speed of the *change* one stage made to the
  pelvis (after - before the stage): how fast that stage drags the body, whatever the motion's own
  speed (per stage, because de-jittering alone "moves" a jittery pelvis at up to 0.8 m/s);
- ``joint_accel`` (m/s^2): the 99th percentile over frames and joints of the acceleration magnitude
  (a percentile, not the maximum, so that one legitimately snapped frame does not trip it);

- ``pelvis_accel`` (m/s^2): the peak acceleration of the pelvis (second difference of its position):
  a one- or two-frame *pelvis pop* shows here and nowhere else (the joint percentile averages it away);
- ``lowest`` (m): the lowest point any joint reaches (the floor is y = 0);

and, for the exact stage, the report's ``max_change_outside_blend_cm``: how far any joint moved on
frames no constraint may touch (it should be 0).

Bounds (``GuardBounds``): a stage may drag the pelvis at most at 3 m/s (``added_pelvis_speed``), and
the result may never be faster than 10 m/s (a sprint) unless the raw motion was already faster, may
raise the joint acceleration to at most ``max(raw + 30 m/s^2, 2 x raw)``, may raise the pelvis' peak
acceleration to at most ``max(input + 15 m/s^2, 1.25 x input)`` (its own input's, since de-jittering
lowers it), and may not move frames outside its blend windows by more than 1 cm. A stage that puts a
joint more than 1 cm lower than both the floor and the raw motion's lowest point is kept (its
constraints need it) but said in the warnings (``floor_note``).

Pelvis pops (issue 36), measured on the shipped model (5-s motions, 17 prompts and examples): foot
locking's pelvis reach raised the pelvis' peak acceleration from 6-15 m/s^2 (de-jittered input) to
37-73 m/s^2 on walks ("A tired person walks slowly.": a 1.7 -> 4.4 m/s pop at frame 30; "A person
walks forward."; inbetween_from_bvh.json; both example timelines), while accepted stages stayed within
15 m/s^2 of their input (waypoints 15.5 -> 27.1, a run with foot contacts 35.2 -> 42.6, the hand
targets' exact pass 0.6 -> 11.0). A foot lock tripping it is redone without moving the pelvis
(kinema.postprocess._guarded_foot_lock), else undone. Measured on the shipped model (5-s motions, the five
examples with walk and run prompts, text-only walks, runs and dances): accepted stages dragged the
pelvis at up to 2.7 m/s; the failures this guards against added 14 m/s (a foot target 3.5 m behind a walk) to
440 m/s (the inverted smoothing of a dense path).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from kinema.errors import KinemaError
from kinema.motion.core import Motion


@dataclass(frozen=True)
class GuardBounds:
    """How much less plausible than the raw motion a post-processing stage may make it (SI units)."""

    added_pelvis_speed: float = 3.0  # m/s, speed of the change made to the pelvis
    pelvis_speed_cap: float = 10.0  # m/s, absolute (unless the raw motion is already faster)
    accel_slack: float = 30.0  # m/s^2 over the raw 99th percentile
    accel_ratio: float = 2.0  # x the raw 99th percentile
    pelvis_accel_slack: float = 15.0  # m/s^2 over the stage input's pelvis acceleration peak
    pelvis_accel_ratio: float = 1.25  # x the stage input's pelvis acceleration peak
    floor_slack_cm: float = 1.0  # cm below both the floor and the raw motion's lowest point
    outside_change_cm: float = 1.0  # cm, frames outside every blend window


DEFAULT_BOUNDS = GuardBounds()


@dataclass(frozen=True)
class Plausibility:
    """Peak pelvis speed (m/s), 99th-percentile joint acceleration (m/s^2), pelvis positions (T, 3),
    peak pelvis acceleration (m/s^2) and its frame, and the lowest joint height (m) with its frame and
    joint."""

    pelvis_speed: float
    joint_accel: float
    pelvis: torch.Tensor
    fps: float
    pelvis_accel: float = 0.0
    pelvis_accel_frame: int = 0
    lowest: float = 0.0
    lowest_at: tuple[int, int] = (0, 0)

    def as_dict(self) -> dict:
        return {"pelvis_speed_m_s": round(self.pelvis_speed, 3), "joint_accel_m_s2": round(self.joint_accel, 2)}

    def added_speed(self, raw: Plausibility) -> float:
        """Peak speed (m/s) of the pelvis displacement from ``raw`` to this motion (same length)."""
        if self.pelvis.shape != raw.pelvis.shape or self.pelvis.shape[0] < 2:
            return 0.0
        change = self.pelvis - raw.pelvis
        return float((change[1:] - change[:-1]).norm(dim=-1).max()) * self.fps


def plausibility(motion: Motion) -> Plausibility:
    """Measure ``motion`` (any dtype; 0 for motions too short to have a speed or an acceleration)."""
    P = motion.positions.to(torch.float64)  # (T, J, 3) metres
    pelvis = P[:, motion.skeleton.roles.get("pelvis", 0)]
    fps = float(motion.fps)
    speed = (pelvis[1:] - pelvis[:-1]).norm(dim=-1) * fps if P.shape[0] > 1 else P.new_zeros(1)
    accel, pelvis_accel, pelvis_frame = 0.0, 0.0, 0
    if P.shape[0] > 2:
        acc = (P[2:] - 2 * P[1:-1] + P[:-2]).norm(dim=-1) * fps**2  # (T - 2, J), frame i + 1
        accel = float(torch.quantile(acc.flatten(), 0.99))
        pelvis_acc = (pelvis[2:] - 2 * pelvis[1:-1] + pelvis[:-2]).norm(dim=-1) * fps**2
        pelvis_accel, pelvis_frame = float(pelvis_acc.max()), int(pelvis_acc.argmax()) + 1
    heights = P[..., 1]
    low = int(heights.argmin())
    return Plausibility(float(speed.max()), accel, pelvis, fps, pelvis_accel, pelvis_frame, float(heights.min()),
                        (low // P.shape[1], low % P.shape[1]))


def violations(
    raw: Plausibility, before: Plausibility, new: Plausibility, bounds: GuardBounds = DEFAULT_BOUNDS,
) -> list[str]:
    """Why ``new`` (a stage's output; ``before`` its input) is less plausible than ``raw`` beyond
    ``bounds`` (empty when it is within them). A stage whose output is not finite gets that one reason."""
    if not (math.isfinite(new.pelvis_speed) and math.isfinite(new.joint_accel) and math.isfinite(new.lowest)):
        return ["it produced NaN or infinite joint positions (a degenerate target it could not solve)"]
    out = []
    added = new.added_speed(before)
    if not added <= bounds.added_pelvis_speed:
        out.append(f"it drags the pelvis at {added:.2f} m/s (limit {bounds.added_pelvis_speed:g})")
    cap = max(bounds.pelvis_speed_cap, raw.pelvis_speed)
    if not new.pelvis_speed <= cap:
        out.append(f"pelvis speed {new.pelvis_speed:.2f} m/s (raw {raw.pelvis_speed:.2f}, limit {cap:.2f})")
    accel_limit = max(raw.joint_accel + bounds.accel_slack, raw.joint_accel * bounds.accel_ratio)
    if not new.joint_accel <= accel_limit:
        out.append(f"joint acceleration {new.joint_accel:.1f} m/s^2 (raw {raw.joint_accel:.1f}, "
                   f"limit {accel_limit:.1f})")
    pop_limit = max(before.pelvis_accel + bounds.pelvis_accel_slack, before.pelvis_accel * bounds.pelvis_accel_ratio)
    if not new.pelvis_accel <= pop_limit:
        out.append(f"a pelvis pop at frame {new.pelvis_accel_frame}: acceleration {new.pelvis_accel:.1f} m/s^2 "
                   f"(before the stage {before.pelvis_accel:.1f}, limit {pop_limit:.1f})")
    return out


def floor_note(raw: Plausibility, new: Plausibility, names, bounds: GuardBounds = DEFAULT_BOUNDS) -> str | None:
    """What to say when ``new`` puts a joint more than ``floor_slack_cm`` below both the floor (y = 0)
    and the raw motion's lowest point (``names``: the skeleton's joint names); None when it does not."""
    allowed = min(raw.lowest, 0.0) - bounds.floor_slack_cm / 100.0
    if new.lowest >= allowed:
        return None
    frame, joint = new.lowest_at
    return (f"{names[joint]} goes {-new.lowest * 100:.1f} cm below the floor at frame {frame} (the raw motion's "
            f"lowest point is {raw.lowest * 100:+.1f} cm)")


def require_finite(motions, stage: str) -> None:
    """A one-line `KinemaError` naming the sample and first frame when ``stage`` (e.g. "sampling") gave
    a motion with NaN or infinite values, instead of a NaN motion that fails later, at save time,
    without a cause (issue 36)."""
    for i, motion in enumerate(motions):
        bad = ~torch.isfinite(motion.root_translation).all(-1) | ~torch.isfinite(motion.local_rotations).all(-1).all(-1)
        if bool(bad.any()):
            frame = int(torch.nonzero(bad)[0])
            raise KinemaError(f"sample {i}: {stage} produced NaN or infinite values (first at frame {frame}); an "
                              "input far outside what the model can take (a huge target, heading or weight?)")
