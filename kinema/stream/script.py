"""Scripted streams: a JSON-lines file of timed commands played into a `MotionStream`.

One object per line, ``t`` (seconds of stream time, not decreasing) and exactly one command::

    {"t": 0, "prompt": "A person walks forward."}
    {"t": 8, "steer": {"direction_deg": 90, "speed": 1.2}}
    {"t": 12, "target": {"joint": "right_hand", "position": [0.3, 1.5, 0.4]}}
    {"t": 14, "clear": true}

Blank lines and lines starting with ``#`` are skipped; ``comment`` keys are ignored. A command is
issued when the stream has handed out every frame before ``t``. Every line is checked before the stream
starts (a target's joint against the stream's skeleton too), and an error names the line.
"""

from __future__ import annotations

import json
import reprlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kinema.errors import KinemaError
from kinema.finite import is_finite_real
from kinema.input_files import read_text_bounded
from kinema.motion.core import Motion
from kinema.stream.continuation import MotionStream
from kinema.stream.controls import DEFAULT_SPEED, MAX_PROMPT_CHARS, Steer, Target
from kinema.stream.measure import JOIN_RADIUS, JoinReport, frames_to_motion, join_report

COMMANDS = ("prompt", "steer", "target", "clear")
#: most commands one script may hold
MAX_COMMANDS = 10_000
#: the longest stream a script plays, and so the latest ``t`` (seconds)
MAX_SECONDS = 3600.0


@dataclass(frozen=True)
class ScriptCommand:
    """``kind`` (one of `COMMANDS`) with its ``value``, issued at stream time ``t`` seconds."""

    t: float
    kind: str
    value: Any
    where: str = "script"  # the file and line, for errors

    def apply(self, stream: MotionStream):
        """Issue the command; returns the stream's `CommandRecord`."""
        if self.kind == "prompt":
            return stream.set_prompt(self.value)
        if self.kind == "steer":
            return stream.steer(**self.value)
        if self.kind == "target":
            return stream.target(self.value["joint"], self.value["position"])
        return stream.clear()

    def check(self, stream: MotionStream) -> None:
        """A target's joint and position checked against ``stream``'s skeleton before it starts."""
        if self.kind == "target":
            skel = stream.skeleton
            try:
                Target.checked(self.value["joint"], self.value["position"], skel.names, skel.roles)
            except KinemaError as err:
                raise KinemaError(f"{self.where}: {err}") from None


def parse_command(obj, where: str) -> ScriptCommand:
    """One script line (a decoded JSON object) as a `ScriptCommand`; ``where`` names it in errors."""
    if not isinstance(obj, dict):
        raise KinemaError(f"{where}: expected a JSON object like {{\"t\": 0, \"prompt\": \"...\"}}")
    t = obj.get("t")
    if not is_finite_real(t) or not 0 <= t <= MAX_SECONDS:
        raise KinemaError(f"{where}: 't' must be a number of seconds in [0, {MAX_SECONDS:g}], got {reprlib.repr(t)}")
    keys = [k for k in obj if k not in ("t", "comment")]
    if len(keys) != 1 or keys[0] not in COMMANDS:
        raise KinemaError(f"{where}: expected exactly one of {', '.join(COMMANDS)} besides 't', got {keys}")
    kind, value = keys[0], obj[keys[0]]
    if kind == "prompt" and not (isinstance(value, str) and len(value) <= MAX_PROMPT_CHARS):
        raise KinemaError(f"{where}: 'prompt' must be a string of at most {MAX_PROMPT_CHARS} characters")
    if kind == "steer" and not (isinstance(value, dict) and set(value) <= {"direction_deg", "speed"}):
        raise KinemaError(f"{where}: 'steer' must be an object with 'direction_deg' and/or 'speed'")
    if kind == "steer":
        try:
            Steer.checked(value.get("direction_deg"), value.get("speed", DEFAULT_SPEED))
        except KinemaError as err:
            raise KinemaError(f"{where}: {err}") from None
    if kind == "target" and not (isinstance(value, dict) and set(value) == {"joint", "position"}):
        raise KinemaError(f"{where}: 'target' must be an object with 'joint' and 'position'")
    if kind == "clear" and value is not True:
        raise KinemaError(f"{where}: 'clear' must be true (it drops steering and targets), got {reprlib.repr(value)}")
    return ScriptCommand(float(t), kind, value, where)


def read_script(path: str | Path) -> list[ScriptCommand]:
    """The commands of a JSON-lines script file, in order (times must not decrease)."""
    path = Path(path)
    lines = read_text_bounded(path, "stream script").splitlines()
    out: list[ScriptCommand] = []
    for i, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            obj = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            raise KinemaError(f"{path}:{i}: not valid JSON") from None
        cmd = parse_command(obj, f"{path}:{i}")
        if out and cmd.t < out[-1].t:
            raise KinemaError(f"{path}:{i}: t = {cmd.t:g} s comes before the previous line's {out[-1].t:g} s")
        out.append(cmd)
        if len(out) > MAX_COMMANDS:
            raise KinemaError(f"{path}: more than {MAX_COMMANDS} commands")
    if not out:
        raise KinemaError(f"{path}: the stream script has no commands")
    return out


@dataclass
class ScriptRun:
    """A played script: the whole motion, the stream (its commands and window timings) and the wall
    seconds spent generating."""

    motion: Motion
    stream: MotionStream
    wall_seconds: float

    @property
    def realtime_factor(self) -> float:
        """Seconds of motion generated per wall second."""
        return self.motion.duration / max(self.wall_seconds, 1e-9)

    def joins(self) -> JoinReport:
        """Pops at the window joins against the windows' own motion (kinema.stream.measure.join_report)."""
        seams = [(lo, hi) for lo, hi in self.stream.seams() if hi + JOIN_RADIUS < self.motion.num_frames]
        return join_report(self.motion, seams)

    def log(self) -> dict:
        """The JSON log: settings, each command's latency, each window's timings, the joins, the totals."""
        s = self.stream.settings
        windows = [{"first_frame": w.first_frame, "new_frames": w.new_frames, "sampling": round(w.sampling, 4),
                    "postprocess": round(w.postprocess, 4), "other": round(w.other, 4)} for w in self.stream.windows]
        return {"fps": s.fps, "frames": self.motion.num_frames, "seconds": round(self.motion.duration, 3),
                "wall_seconds": round(self.wall_seconds, 3), "realtime_factor": round(self.realtime_factor, 2),
                "window_seconds": s.window / s.fps, "steps": s.steps, "lookahead_seconds": s.lookahead / s.fps,
                "commands": [c.to_json() for c in self.stream.commands], "windows": windows,
                "joins": self.joins().to_json()}


def run_script(stream: MotionStream, commands: list[ScriptCommand], seconds: float,
               chunk_seconds: float = 0.5) -> ScriptRun:
    """Play ``commands`` into ``stream`` for ``seconds`` of motion, pulling ``chunk_seconds`` at a time."""
    if not (is_finite_real(seconds) and seconds > 0):
        raise KinemaError(f"seconds must be a positive number, got {seconds!r}")
    if seconds > MAX_SECONDS:
        raise KinemaError(f"seconds must be at most {MAX_SECONDS:g}, got {seconds:g}")
    for command in commands:
        command.check(stream)
    fps = stream.fps
    total = max(1, round(seconds * fps))
    chunk = max(1, round(chunk_seconds * fps))
    issue_at = [min(total, round(c.t * fps)) for c in commands]
    parts, pending, wall = [], 0, 0.0
    while stream.frames_out < total:
        t0 = time.perf_counter()
        while pending < len(commands) and issue_at[pending] <= stream.frames_out:
            commands[pending].apply(stream)
            pending += 1
        upcoming = issue_at[pending] if pending < len(commands) else total
        n = min(chunk, total - stream.frames_out, max(1, upcoming - stream.frames_out))
        parts.append(stream.next_frames(n))
        wall += time.perf_counter() - t0
    return ScriptRun(frames_to_motion(parts, stream.skeleton), stream, wall)
