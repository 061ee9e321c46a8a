"""What one app tab is editing: the timeline, the constraints and the generation settings, and the
session file that saves them (JSON, read back by "Load session" and usable piece by piece by the CLI).

Session file::

    {"kinema_session": 1, "fps": 20,
     "timeline": [{"prompt": "A person walks forward.", "seconds": 6.0}, ...],
     "constraints": [{"type": "root2d", "frame_indices": [40], "smooth_root_2d": [[1.0, 2.0]]}, ...],
     "settings": {"samples": 2, "seed": 0, "steps": 10}}

``timeline`` is a ``kinema generate --timeline`` file and ``constraints`` a ``--constraints`` file
(docs/constraints.md) whose ``frame_indices`` are at ``fps``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

from kinema.constraints import constraint_to_json, load_constraints
from kinema.errors import KinemaError
from kinema.pipeline.timeline import parse_timeline

SESSION_VERSION = 1
SESSION_KEYS = ("kinema_session", "fps", "timeline", "constraints", "settings")
SETTING_KEYS = ("samples", "seed", "steps")
DEFAULT_TIMELINE = (
    {"prompt": "A person walks forward.", "seconds": 6.0},
    {"prompt": "A person waves.", "seconds": 5.0},  # a prompt the model knows (a turn and a wave never share a caption)
)


#: the shortest segment a session may hold (the Seconds boxes' lower end)
MIN_SEGMENT_SECONDS = 0.5
#: the longest segment a session may hold (the Seconds boxes' range; longer stretches are several segments)
MAX_SEGMENT_SECONDS = 60.0
#: the longest timeline a session may hold (a few minutes of motion: many minutes of CPU)
MAX_SESSION_SECONDS = 180.0


@dataclass
class Settings:
    """Generation settings of a tab: samples side by side (1-4), seed, DDIM steps (None = model's)."""

    samples: int = 2
    seed: int = 0
    steps: int | None = None


@dataclass
class Document:
    """The editable state of a tab (no motions: those are results, regenerated from this)."""

    timeline: list[dict] = field(default_factory=lambda: [dict(s) for s in DEFAULT_TIMELINE])
    constraints: list[dict] = field(default_factory=list)
    settings: Settings = field(default_factory=Settings)

    def seconds(self) -> float:
        """Total duration of the timeline, seconds."""
        return float(sum(s["seconds"] for s in self.timeline))

    def num_frames(self, fps: float) -> int:
        """Frames the generated motion will have (segments add up; see kinema.pipeline.timeline)."""
        return sum(round(s["seconds"] * fps) for s in self.timeline)

    def segment_starts(self, fps: float) -> list[int]:
        """The first frame of each timeline segment (as :meth:`num_frames` counts them)."""
        starts, frame = [], 0
        for s in self.timeline:
            starts.append(frame)
            frame += round(s["seconds"] * fps)
        return starts

    def to_json(self, fps: float) -> str:
        """The session file's text."""
        obj = {
            "kinema_session": SESSION_VERSION,
            "fps": fps,
            "timeline": self.timeline,
            "constraints": self.constraints,
            "settings": vars(self.settings),
        }
        return json.dumps(obj, indent=1, allow_nan=False) + "\n"


def creature_prompts(rig_name: str) -> tuple[dict, ...]:
    """The default timeline for a model for any rig: the rig's file name as the subject (``Fox.glb``:
    "A fox walks."), "A creature" when the name has no word."""
    words = re.sub(r"[^a-z]+", " ", rig_name.rsplit(".", 1)[0].lower()).split()
    noun = " ".join(words[:2]) or "creature"
    article = "An" if noun[0] in "aeiou" else "A"
    return (
        {"prompt": f"{article} {noun} walks.", "seconds": 6.0},
        {"prompt": f"{article} {noun} turns around.", "seconds": 5.0},
    )


def added_prompt(any_rig: bool, rig_name: str) -> str:
    """What "Add prompt" writes: a person (human model) or the rig's subject (any-rig model) standing still."""
    return (
        creature_prompts(rig_name)[0]["prompt"].replace(" walks.", " stands still.")
        if any_rig
        else "A person stands still."
    )


def default_document(any_rig: bool, rig_name: str, settings: Settings) -> Document:
    """A new tab's document: two prompts about a person (human model) or about the rig (any-rig model)."""
    timeline = creature_prompts(rig_name) if any_rig else DEFAULT_TIMELINE
    return Document(timeline=[dict(s) for s in timeline], settings=settings)


def check_timeline(timeline: list[dict]) -> list[dict]:
    """The timeline validated by the generator's own parser, as plain ``{"prompt", "seconds"}`` dicts."""
    return [{"prompt": s.prompt, "seconds": float(s.seconds)} for s in parse_timeline(list(timeline), "timeline")]


def check_session_length(timeline: list[dict], source: str) -> None:
    """Refuse a segment shorter or longer than the Seconds boxes take, or a timeline longer than a session may be."""
    for i, seg in enumerate(timeline):
        if not MIN_SEGMENT_SECONDS <= seg["seconds"] <= MAX_SEGMENT_SECONDS:
            raise KinemaError(
                f"{source}: timeline[{i}]: 'seconds' is {seg['seconds']:g}; a segment lasts "
                f"{MIN_SEGMENT_SECONDS:g} to {MAX_SEGMENT_SECONDS:g} s in the app (split a longer "
                "one into several prompts)"
            )
    total = sum(seg["seconds"] for seg in timeline)
    if total > MAX_SESSION_SECONDS:
        raise KinemaError(
            f"{source}: the timeline lasts {total:g} s; a session holds at most {MAX_SESSION_SECONDS:g} s"
        )


def _settings(obj, source: str, max_steps: int) -> Settings:
    if not isinstance(obj, dict):
        raise KinemaError(f"{source}: 'settings' must be an object with {list(SETTING_KEYS)}")
    unknown = sorted(set(obj) - set(SETTING_KEYS))
    if unknown:
        raise KinemaError(f"{source}: settings: unknown keys {unknown} (expected {list(SETTING_KEYS)})")
    s = Settings(**obj)
    for name, low, high in (("samples", 1, 4), ("seed", 0, 2**64 - 1), ("steps", 1, max_steps)):
        v = getattr(s, name)
        if name == "steps" and v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
            raise KinemaError(f"{source}: settings: '{name}' must be an integer in [{low}, {high}], got {v!r}")
    return s


def load_document(
    text: str | bytes, *, skeleton, fps: float, source: str = "session", max_steps: int = 10**6
) -> Document:
    """Parse and validate a whole session file against the model (skeleton, fps, its most DDIM steps) and
    the app's limits (`check_session_length`); errors name the field."""
    try:
        obj = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise KinemaError(f"{source}: not a JSON session file ({err})") from None
    if not isinstance(obj, dict) or obj.get("kinema_session") != SESSION_VERSION:
        raise KinemaError(
            f'{source}: not a kinema session file (expected an object with "kinema_session": '
            f"{SESSION_VERSION}, as 'Download session' writes)"
        )
    unknown = sorted(set(obj) - set(SESSION_KEYS))
    if unknown:
        raise KinemaError(f"{source}: unknown keys {unknown} (expected {list(SESSION_KEYS)})")
    file_fps = obj.get("fps", fps)
    if (
        isinstance(file_fps, bool)
        or not isinstance(file_fps, int | float)
        or not (math.isfinite(file_fps) and file_fps > 0)
    ):
        raise KinemaError(f"{source}: 'fps' must be a positive number, got {file_fps!r}")
    timeline = check_timeline(obj.get("timeline", []))
    check_session_length(timeline, source)
    frames = sum(round(s["seconds"] * fps) for s in timeline)
    cons = load_constraints({"fps": file_fps, "constraints": obj.get("constraints", [])}, skeleton, fps, frames)
    settings = _settings(obj.get("settings", {}), source, max_steps)
    return Document(timeline=timeline, constraints=[constraint_to_json(c) for c in cons], settings=settings)
