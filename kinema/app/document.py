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
from dataclasses import dataclass, field

from kinema.constraints import constraint_to_json, load_constraints
from kinema.errors import KinemaError
from kinema.pipeline.timeline import parse_timeline

SESSION_VERSION = 1
SESSION_KEYS = ("kinema_session", "fps", "timeline", "constraints", "settings")
SETTING_KEYS = ("samples", "seed", "steps")
DEFAULT_TIMELINE = (
    {"prompt": "A person walks forward.", "seconds": 6.0},
    {"prompt": "A person turns around and waves.", "seconds": 5.0},
)


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


def check_timeline(timeline: list[dict]) -> list[dict]:
    """The timeline validated by the generator's own parser, as plain ``{"prompt", "seconds"}`` dicts."""
    return [{"prompt": s.prompt, "seconds": float(s.seconds)} for s in parse_timeline(list(timeline), "timeline")]


def _settings(obj, source: str) -> Settings:
    if not isinstance(obj, dict):
        raise KinemaError(f"{source}: 'settings' must be an object with {list(SETTING_KEYS)}")
    unknown = sorted(set(obj) - set(SETTING_KEYS))
    if unknown:
        raise KinemaError(f"{source}: settings: unknown keys {unknown} (expected {list(SETTING_KEYS)})")
    s = Settings(**obj)
    for name, low, high in (("samples", 1, 4), ("seed", 0, 2**64 - 1), ("steps", 1, 10**6)):
        v = getattr(s, name)
        if name == "steps" and v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
            raise KinemaError(f"{source}: settings: '{name}' must be an integer in [{low}, {high}], got {v!r}")
    return s


def load_document(text: str | bytes, *, skeleton, fps: float, source: str = "session") -> Document:
    """Parse and validate a session file against the model (skeleton, fps); errors name the field."""
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
    frames = sum(round(s["seconds"] * fps) for s in timeline)
    cons = load_constraints({"fps": file_fps, "constraints": obj.get("constraints", [])}, skeleton, fps, frames)
    settings = _settings(obj.get("settings", {}), source)
    return Document(timeline=timeline, constraints=[constraint_to_json(c) for c in cons], settings=settings)
