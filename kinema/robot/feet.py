"""Planted feet for the robot: which frames a source foot is planted on, and sole targets that hold still
while it is.

A foot is planted where both its heel (ankle) and toe contact channels are on (kinema.motion.contacts),
after one-frame gaps are filled and one-frame blips dropped. While planted, a sole target holds the value
it had when the foot landed (position on the floor, heading, flat); around each planted span the
difference between held and source values is ramped in before landing and out after lift-off over
``RAMP_FRAMES`` frames, so no target jumps.
"""

from __future__ import annotations

import numpy as np

RAMP_FRAMES = 4
#: A step's swing: the sole's lowest point at least CLEARANCE high at mid-swing (m), so that the robot does
#: not shuffle. The foot is down where it is planted, or within DOWN_HEIGHT of its planted height (m, robot
#: scale) and slower than SWING_SPEED (m/s: a generated foot that skates over the floor faster than that
#: is stepping); a swing is a span of frames on which it is not down, in which it moves at least STEP_MIN
#: (m) in at least MIN_SWING and at most MAX_SWING seconds (longer flights keep the source's lift; a
#: shorter one is a foot that jumps along the floor, where a generated foot skates into its landing, which no
#: arch that fast could follow).
CLEARANCE, DOWN_HEIGHT, SWING_SPEED, STEP_MIN, MIN_SWING, MAX_SWING = 0.05, 0.015, 0.5, 0.05, 0.15, 1.5


def clean_flags(flags: np.ndarray) -> np.ndarray:
    """(T,) bool with one-frame gaps filled and one-frame spans removed."""
    f = flags.astype(bool).copy()
    for t in range(1, len(f) - 1):
        if not f[t] and f[t - 1] and f[t + 1]:
            f[t] = True
    for t in range(len(f)):
        if f[t] and (t == 0 or not f[t - 1]) and (t == len(f) - 1 or not f[t + 1]):
            f[t] = False
    return f


def spans(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) frame of each run of True in (T,) bool flags."""
    out, start = [], None
    for t, on in enumerate(flags):
        if on and start is None:
            start = t
        if not on and start is not None:
            out.append((start, t - 1))
            start = None
    if start is not None:
        out.append((start, len(flags) - 1))
    return out


def hold_planted(source: np.ndarray, planted: np.ndarray, held: np.ndarray | None = None) -> np.ndarray:
    """(T, D) targets equal to ``source`` except on planted spans, where they keep the span's first value
    (or ``held`` (D,) when given, e.g. height 0 or pitch 0), with the difference ramped in and out."""
    out = source.astype(float).copy()
    T = len(source)
    for a, b in spans(planted):
        value = source[a] if held is None else np.broadcast_to(held, source.shape[1:])
        out[a : b + 1] = value
        for k in range(1, RAMP_FRAMES + 1):
            w = 1.0 - k / (RAMP_FRAMES + 1)
            if a - k >= 0 and not planted[a - k]:
                out[a - k] += w * (value - source[a])
            if b + k < T and not planted[b + k]:
                out[b + k] += w * (value - source[b])
    return out


def swing_arches(ground: np.ndarray, down: np.ndarray, fps: float) -> np.ndarray:
    """(T,) a smooth ``sin^2`` arch from 0 to 1 and back over each step's swing (see CLEARANCE), 0 elsewhere:
    times CLEARANCE, the least height of the sole's lowest point. ``ground`` (T, 2): the sole's ground
    position; ``down`` (T,) bool: the frames on which the foot is down (see DOWN_HEIGHT)."""
    out = np.zeros(len(down))
    for a, b in spans(~down):
        if not MIN_SWING <= (b - a + 1) / fps <= MAX_SWING or np.linalg.norm(ground[b] - ground[a]) < STEP_MIN:
            continue
        phase = (np.arange(a, b + 1) - a + 1) / (b - a + 2)
        out[a : b + 1] = np.sin(np.pi * phase) ** 2
    return out
