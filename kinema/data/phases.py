"""Phases of a locomotion capture: starting from rest, steady motion, stopping (issue 57).

Issue 57 asked for captions that tell starting, steady motion, slowing and stopping apart, on the
assumption that every Bandai Namco run crosses the capture room from standing to standing, so that the
model learned "a run is a start, a run and a stop". Measured with :func:`find_phases` on the train split
(source clips; ``python scripts/clip_phases.py cache/bandai20p``), the captures hold no such phases: they
were cut to the moving part. 0 of 243 runs, 0 of 12 dashes, 0 of 12 backward walks and 0 of 23 sideways
walks start or end at rest; 2 of 146 walks start at rest and none ends at rest; the steady stretch covers
almost the whole clip (runs: median 2.90 s of 3.15 s). A run clip runs at 1.6-3.2 m/s from its first
frame to its last. What the model learned is the *length*: a run lasts about 3 s, the length of its
captures, and then it stops (kinema.human.continuation makes longer prompts window by window instead).

- **steady**: the longest stretch at >= ``STEADY_SHARE`` of the clip's cruising speed (the 90th
  percentile of the smoothed ground speed);
- **starts at rest** / **ends at rest**: the first / last ``EDGE_SECONDS`` move at under ``REST_SHARE``
  of the cruising speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from kinema.representation.kimodo_features import features_to_motion

#: the contents that travel
LOCOMOTION = ("walk", "run", "dash", "walk-back", "walk-left", "walk-right")

#: share of the cruising speed (90th percentile of the smoothed speed) that counts as steady motion
STEADY_SHARE = 0.8
#: a clip "starts from rest" / "ends at rest" when its first / last EDGE_SECONDS move below this share
REST_SHARE = 0.4
EDGE_SECONDS = 0.25
#: the speed profile is smoothed over this Gaussian sigma (s): strides make the pelvis surge and slow
SMOOTH_SECONDS = 0.25
#: a clip cruising slower than this (m/s) is not travelling: no phases
MIN_CRUISE_SPEED = 0.3
#: the steady stretch must last this long (s) to be a phase of its own
MIN_STEADY_SECONDS = 1.0


@dataclass(frozen=True)
class Phases:
    """A locomotion clip's phases in frames: the steady stretch ``[steady_start, steady_end)``, whether the
    clip starts and ends at rest, and speeds (m/s) over the steady stretch and the whole clip."""

    num_frames: int
    steady_start: int
    steady_end: int
    starts_at_rest: bool
    ends_at_rest: bool
    steady_speed: float
    cruise_speed: float

    @property
    def steady_seconds_share(self) -> float:
        """The share of the clip that is steady motion."""
        return (self.steady_end - self.steady_start) / max(self.num_frames, 1)


def speed_profile(root_xz: torch.Tensor, fps: float) -> torch.Tensor:
    """Ground speed (m/s) per frame of a pelvis path ``(T, 2)``, Gaussian-smoothed over SMOOTH_SECONDS."""
    xz = root_xz.double()
    v = torch.zeros(xz.shape[0], dtype=torch.float64)
    if xz.shape[0] < 2:
        return v
    step = (xz[1:] - xz[:-1]).norm(dim=-1) * fps
    v[1:] += step
    v[:-1] += step
    v[1:-1] /= 2
    sigma = SMOOTH_SECONDS * fps
    radius = max(1, int(3 * sigma))
    k = torch.exp(-0.5 * (torch.arange(-radius, radius + 1, dtype=torch.float64) / sigma) ** 2)
    padded = torch.cat([v[:1].expand(radius), v, v[-1:].expand(radius)])
    return torch.nn.functional.conv1d(padded[None, None], (k / k.sum())[None, None])[0, 0]


def find_phases(root_xz: torch.Tensor, fps: float) -> Phases | None:
    """The phases of a clip from its pelvis ground path ``(T, 2)`` (metres), or None when it does not travel
    or has no steady stretch of MIN_STEADY_SECONDS."""
    v = speed_profile(root_xz, fps)
    T = v.shape[0]
    if T < 2:
        return None
    cruise = float(torch.quantile(v, 0.9))
    if cruise < MIN_CRUISE_SPEED:
        return None
    steady = (v >= STEADY_SHARE * cruise).tolist()
    best, run_start = (0, 0), None
    for i, s in enumerate(steady + [False]):
        if s and run_start is None:
            run_start = i
        elif not s and run_start is not None:
            if i - run_start > best[1] - best[0]:
                best = (run_start, i)
            run_start = None
    a, b = best
    if (b - a) < MIN_STEADY_SECONDS * fps:
        return None
    edge = max(1, int(round(EDGE_SECONDS * fps)))
    xz = root_xz.double()
    steady_speed = float((xz[b - 1] - xz[a]).norm()) * fps / max(b - 1 - a, 1)
    return Phases(
        num_frames=T, steady_start=a, steady_end=b,
        starts_at_rest=bool(v[:edge].mean() < REST_SHARE * cruise),
        ends_at_rest=bool(v[-edge:].mean() < REST_SHARE * cruise),
        steady_speed=steady_speed, cruise_speed=cruise,
    )


def steady_speeds(dataset, records) -> list[float | None]:
    """Per record of ``dataset`` (a kinema.data.dataset.MotionDataset) its steady speed (m/s), None for a
    clip that does not travel: what a known caption's speed is measured from."""
    return [None if (p := clip_phases(dataset, rec)) is None else p.steady_speed for rec in records]


def clip_phases(dataset, rec: dict) -> Phases | None:
    """:func:`find_phases` of one clip record of ``dataset`` (a kinema.data.dataset.MotionDataset)."""
    feats = dataset.features[rec["start"] : rec["start"] + rec["length"]].double()
    motion = features_to_motion(feats, dataset.skeleton, dataset.fps)
    return find_phases(motion.root_translation[:, [0, 2]], dataset.fps)
