"""The tab's camera: frame the character when a motion is shown (its size and the samples beside it fit
the view, whatever the rig's scale: a fox as well as a person) and follow it while it plays (the camera
keeps the angle the user orbited to and moves with the selected sample's root).

Positions are world metres, Y up. ``direction`` is where the camera stands seen from what it looks at.
"""

from __future__ import annotations

import math
import time
from collections import deque

import numpy as np

#: the default view: from the character's left (+X), above, looking a little ahead along +Z
VIEW_DIRECTION = np.array([4.4, 4.4, -2.4]) / np.linalg.norm([4.4, 4.4, -2.4])
#: room around the character (1 = its bounding sphere touches the view's edges)
MARGIN = 1.35
#: the camera follows once the character's root has moved this far (metres) since the last move
FOLLOW_STEP = 0.02
#: seconds a pose the server set may still come back from the browser (its echo, not a user's move)
ECHO_SECONDS = 2.0


def frame_view(points: np.ndarray, fov: float, direction=VIEW_DIRECTION) -> tuple[np.ndarray, np.ndarray]:
    """(camera position, look-at point) that fit ``points`` (N, 3) in a vertical field of view ``fov``
    (radians), seen from ``direction``."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, hi = pts.min(0), pts.max(0)
    centre = (lo + hi) / 2
    radius = max(0.25, float(np.linalg.norm(hi - lo)) / 2)
    distance = MARGIN * radius / math.sin(min(max(fov, 0.2), 2.5) / 2)
    return centre + np.asarray(direction, dtype=np.float64) * distance, centre


def character_extent(positions: np.ndarray, frame: int, lanes: list[float]) -> np.ndarray:
    """The points to frame: the selected motion's pose at ``frame`` (T, J, 3 positions) and the widest
    pose of the whole motion around it, repeated at every sample lane's X offset (lanes: 0 = selected)."""
    f = int(np.clip(frame, 0, len(positions) - 1))
    pose = positions[f]
    root = pose[0]
    widest = (positions - positions[:, :1]).reshape(-1, 3)
    span = np.stack([widest.min(0), widest.max(0)]) + root
    span[:, 1] = (min(0.0, span[0, 1]), span[1, 1])  # the floor under it stays in view
    return np.concatenate([span + np.array([x, 0.0, 0.0]) for x in lanes] + [pose])


def opening_view(motion, fov: float) -> tuple[np.ndarray, np.ndarray]:
    """(camera position, look-at) that frame ``motion`` (what a new tab shows first) at its first frame:
    the view a page starts from, so a page that sets up its starting view late still frames it."""
    positions = motion.positions.detach().double().numpy()
    return frame_view(character_extent(positions, 0, [0.0]), fov)


class CameraFollow:
    """Frames and follows the shown character in one tab (``client.camera``); ``enabled`` is read from
    the "Follow character" checkbox: it follows while the motion plays and while the user scrubs (a paused
    view left behind showed empty ground, and play kept the offset).

    The browser reports the camera back some frames after the server sets it, so the pose read from
    ``client.camera`` lags what was set: moving that stale pose by each step lost steps (a live character
    walked out of view in 20 s) and undid a framing. The camera is moved from the pose last set instead,
    unless the browser reports one that was never set in the last `ECHO_SECONDS`: the user's own orbit."""

    def __init__(self, client, enabled):
        self.client, self.enabled = client, enabled
        self.target: np.ndarray | None = None
        self._sent: deque[tuple[float, np.ndarray, np.ndarray]] = deque()  # (time, position, look_at) set

    def _pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(position, look_at) to move from: the last pose set, or the user's when the browser reports a
        pose the server did not set."""
        cam = self.client.camera
        reported = (np.asarray(cam.position, dtype=np.float64), np.asarray(cam.look_at, dtype=np.float64))
        now = time.time()
        while self._sent and now - self._sent[0][0] > ECHO_SECONDS:
            self._sent.popleft()
        if not self._sent:
            return reported
        ours = any(np.allclose(reported[0], p, atol=1e-3) and np.allclose(reported[1], q, atol=1e-3)
                   for _, p, q in self._sent)
        return (self._sent[-1][1], self._sent[-1][2]) if ours or cam.update_timestamp < self._sent[-1][0] else reported

    def _set(self, position: np.ndarray, look_at: np.ndarray) -> None:
        cam = self.client.camera
        cam.position = tuple(float(v) for v in position)
        cam.look_at = tuple(float(v) for v in look_at)
        self._sent.append((time.time(), np.asarray(position, dtype=np.float64),
                           np.asarray(look_at, dtype=np.float64)))

    def frame(self, points: np.ndarray, target, *, keep_zoom: bool = False) -> None:
        """Point the camera at ``points``; ``target``: the root it then follows. The first time from the
        default angle, then from the angle the user orbited to (a new motion or F does not undo the user's
        view), and with ``keep_zoom`` no closer than the user had it."""
        position, look_at = self._pose()
        direction, user = VIEW_DIRECTION, position - look_at
        if self.target is not None and float(np.linalg.norm(user)) > 1e-6:
            direction = user / np.linalg.norm(user)
        position, look_at = frame_view(points, float(self.client.camera.fov), direction)
        if keep_zoom and self.target is not None:
            position = look_at + direction * max(float(np.linalg.norm(user)), float(np.linalg.norm(position - look_at)))
        self._set(position, look_at)
        self.target = np.asarray(target, dtype=np.float64)

    def follow(self, target) -> None:
        """Move the camera with the root (same angle and distance) while "Follow character" is on."""
        target = np.asarray(target, dtype=np.float64)
        if self.target is None or not self.enabled():
            self.target = target
            return
        delta = target - self.target
        delta[1] = 0.0
        if float(np.linalg.norm(delta)) < FOLLOW_STEP:
            return
        position, look_at = self._pose()
        self._set(position + delta, look_at + delta)
        self.target = target
