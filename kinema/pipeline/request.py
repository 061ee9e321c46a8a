"""`GenerationRequest`: everything a user can ask of a generation, in one frozen dataclass.

Every face derives its input from this class instead of writing the options again: the CLI's flags
(kinema.pipeline.request_cli), the server's and batch's JSON schemas (kinema.pipeline.request_json) and
the app's call. Each field carries an `Option` in its metadata: the help text, the bounds (they live
here once; `check` enforces them for Python callers, the CLI's types and the JSON schemas are built from
them) and how a face spells the field (a flag name, a JSON type).

Units: seconds, metres, radians (``heading``; the CLI's ``--heading`` takes degrees), frames at the
model's fps unless ``constraints_fps`` says otherwise. Values a model fills in (steps, guidance,
grounding) are None when not given.
"""

from __future__ import annotations

import dataclasses
import os
import reprlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from kinema.errors import KinemaError
from kinema.finite import is_finite_real
from kinema.runtime import positive_from_env

#: largest seed `torch.Generator.manual_seed` takes as it is
MAX_SEED = 2**64 - 1
DEFAULT_SECONDS = 5.0
#: environment variables that raise (or lower) a bound for a process: field -> variable
BOUND_ENV = {"max_seconds": "KINEMA_MAX_SECONDS", "max_samples": "KINEMA_MAX_SAMPLES"}


@dataclass(frozen=True)
class RequestBounds:
    """The largest request kinema accepts on any face (a server's limits can only be tighter).

    Memory and time grow with seconds x samples: a 600-s motion is 12 000 frames at 20 fps, the longest
    timeline the human model's joins were measured on; 64 samples of a 10-s window fill about 2 GB of
    activations. ``KINEMA_MAX_SECONDS`` and ``KINEMA_MAX_SAMPLES`` override the first two for a process.
    """

    max_seconds: float = 600.0
    max_samples: int = 64
    max_steps: int = 1000
    max_guidance: float = 100.0
    max_fps: float = 240.0
    max_prompt_chars: int = 2000

    @classmethod
    def from_env(cls) -> RequestBounds:
        """The defaults with the environment's overrides (a bad value is a one-line error naming it)."""
        given = {f: positive_from_env(env, getattr(cls, f), integer=f == "max_samples") for f, env in BOUND_ENV.items()}
        return cls(**given)


def request_bounds() -> RequestBounds:
    """The bounds every request is checked against: the defaults and the environment's overrides."""
    return RequestBounds.from_env()


@dataclass(frozen=True)
class Option:
    """How a request field is described, bounded and spelled by the faces.

    ``kind`` is the JSON shape: "str", "int", "float", "bool", "pair" (two floats), "json" (a JSON
    list/object: constraints, objectives, timeline segments, an inline rig). ``low``/``high`` bound
    numbers (``high`` may name a `RequestBounds` attribute); ``open_low`` excludes ``low`` itself.
    ``cli`` is the flag (default ``--name-with-dashes``); ``cli=False`` keeps a field off the command
    line (``cli_note`` says why and where the CLI takes it instead). ``file`` fields take a path on the
    CLI and in batch lines (read relative to the jobs file), the value itself in the server.
    """

    help: str
    kind: str = "str"
    low: float | None = None
    high: float | str | None = None
    open_low: bool = False
    choices: tuple[str, ...] | None = None
    cli: str | bool = True
    cli_note: str = ""
    file: bool = False
    metavar: str | None = None
    objects: bool = False

    def high_value(self, bounds: RequestBounds) -> float | None:
        return getattr(bounds, self.high) if isinstance(self.high, str) else self.high


def option(default: Any, **kw) -> Any:
    """A dataclass field with its `Option` in the metadata."""
    if isinstance(default, list | dict):
        return field(default_factory=lambda: default, metadata={"option": Option(**kw)})
    return field(default=default, metadata={"option": Option(**kw)})


@dataclass(frozen=True, kw_only=True)
class GenerationRequest:
    """What to generate. Give ``prompt`` (+ ``seconds``) or ``timeline``; everything else is optional."""

    prompt: str = option("", help='what the character does ("" = no text)', high="max_prompt_chars", cli="PROMPT")
    timeline: Any = option(None, kind="json", file=True, metavar="FILE",
                           help="several prompts in sequence: a list of {prompt, seconds} (docs/formats.md)")
    seconds: float | None = option(None, kind="float", low=0, open_low=True, high="max_seconds",
                                   help=f"duration of a single prompt (default {DEFAULT_SECONDS:g}; 4 for a model for "
                                        "any rig)")
    samples: int = option(1, kind="int", low=1, high="max_samples",
                          help="how many motions (same request, different noise), sampled as one batch")
    seed: int = option(0, kind="int", low=0, high=MAX_SEED, help="random seed: fixes the result")
    steps: int | None = option(None, kind="int", low=1, high="max_steps",
                               help="DDIM steps (default: the model's setting)")
    guidance: tuple[float, float] | None = option(None, kind="pair", low=0, high="max_guidance",
                                                  metavar=("W_TEXT", "W_CONSTR"), objects=True,
                                                  help="separated guidance weights, text and constraints on their own "
                                                       "(default: the model's own guidance; docs/constraints.md)")
    constraints: Any = option(None, kind="json", file=True, metavar="FILE",
                              help="keyframes, end effectors, waypoints, paths, foot contacts (docs/constraints.md)")
    constraints_fps: float | None = option(None, kind="float", low=0, open_low=True, high="max_fps", metavar="FPS",
                                           help="frame rate of the constraints' frame_indices (default: the model's)")
    objectives: Any = option(None, kind="json", cli=False, cli_note="the constraints file's 'objectives'",
                             help="implicit controls met by optimising the noise (docs/objectives.md)")
    objective_steps: int | None = option(None, kind="int", low=0, high=1000, metavar="N",
                                         help="noise-optimisation iterations for objectives (default 12)")
    heading: float = option(0.0, kind="float", low=-360.0, high=360.0,
                            help="first-frame facing about +Y, radians (0 faces +Z; the CLI takes degrees)")
    postprocess: bool = option(True, kind="bool", help="foot locking, IK and exact constraint hits (guarded)")
    grounding: float | None = option(None, kind="float", low=0, high=1, metavar="WEIGHT",
                                     help="prompt grounding weight on the nearest training captions "
                                          "(0 = off; default: the model's setting)")
    grounding_top_k: int | None = option(None, kind="int", low=1, high=100, metavar="K",
                                         help="nearest training captions blended in (default: the model's)")
    grounding_temperature: float | None = option(None, kind="float", low=0, open_low=True, high=100, metavar="T",
                                                 help="softmax temperature of grounding (default: the model's)")
    keyjoint_model: str | None = option(None, metavar="MODEL", objects=True,
                                        help="plan pelvis, head, hands and feet from sparse targets first "
                                             "('default' or a keyjoint model folder; 'none' = off; unset: "
                                             "'default' for sparse joint targets alone; docs/constraints.md)")
    rig: Any = option(None, kind="json", metavar="RIG",
                      help="the character: a GLB/BVH file, a training rig id, or inline {format, data}")
    robot: str | None = option(None, metavar="ROBOT",
                               help="also give the motion on a humanoid robot: 'g1', 'h1' or an MJCF file "
                                    "(docs/robots.md); the output is the robot's joint angles (.csv or .npz)")
    robot_mapping: Any = option(None, kind="json", file=True, metavar="FILE",
                                help="which robot body is which human joint, for an MJCF whose names kinema does not "
                                     "know (docs/robots.md)")
    fps: float | None = option(None, kind="float", low=0, open_low=True, high="max_fps",
                               help="resample the output to this frame rate (default: the model's)")
    format: str | None = option(None, choices=("bvh", "bvh.gz", "npz", "glb", "json", "csv"), cli=False,
                                cli_note="the suffix of --out",
                                help="output format (default bvh)")

    def __post_init__(self) -> None:
        check(self)

    # ------------------------------------------------------------------ conveniences
    def replace(self, **changes) -> GenerationRequest:
        """A copy with some fields changed (checked again)."""
        return dataclasses.replace(self, **changes)

    def segments_json(self) -> list[dict]:
        """The request as a timeline list: the segments, or the prompt with its seconds (default 5 s)."""
        if isinstance(self.timeline, str | os.PathLike):
            raise KinemaError(f"timeline {self.timeline}: read the file first (kinema.pipeline.timeline)")
        if self.timeline is not None:
            return [segment_json(s, i) for i, s in enumerate(self.timeline)]
        return [{"prompt": self.prompt, "seconds": DEFAULT_SECONDS if self.seconds is None else self.seconds}]

    def total_seconds(self) -> float:
        """The output's duration (a timeline's segments added up); segments not yet checked count as 0."""
        total = 0.0
        for s in self.segments_json():
            v = s.get("seconds")
            total += float(v) if is_finite_real(v) else 0.0
        return total

    def grounding_settings(self) -> dict | None:
        """The grounding fields that were given, as ``Grounding`` keys (None: the model's default)."""
        given = {"weight": self.grounding, "top_k": self.grounding_top_k, "temperature": self.grounding_temperature}
        given = {k: v for k, v in given.items() if v is not None}
        return given or None

    def to_json(self) -> dict:
        """The fields that differ from their defaults, as JSON values (what a batch line or a server body holds)."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value != f.default and not (f.default_factory is not dataclasses.MISSING
                                            and value == f.default_factory()):
                out[f.name] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_json(cls, data: Mapping, where: str = "request") -> GenerationRequest:
        """A request from a JSON object (unknown keys are one-line errors naming ``where``)."""
        if not isinstance(data, Mapping):
            raise KinemaError(f"{where}: expected a JSON object, got {type(data).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise KinemaError(f"{where}: unknown field {unknown[0]!r} (known: {', '.join(sorted(names))})")
        values = dict(data)
        if isinstance(values.get("guidance"), list):
            values["guidance"] = tuple(values["guidance"])
        return cls(**values)


def options(cls: type = GenerationRequest) -> list[tuple[dataclasses.Field, Option]]:
    """The fields of a request class with their `Option`s, in declaration order."""
    return [(f, f.metadata["option"]) for f in dataclasses.fields(cls) if "option" in f.metadata]


# ---------------------------------------------------------------------- checks
def _range(opt: Option, bounds: RequestBounds, integer: bool) -> str:
    """The field's range in words: ``an integer in [1, 1000]``, ``a finite number > 0``, ..."""
    low, high = opt.low, opt.high_value(bounds)
    fmt = (lambda x: f"{int(x)}") if integer else (lambda x: f"{x:g}")
    what = "an integer" if integer else "a finite number"
    if low is not None and high is not None:
        return f"{what} in {'(' if opt.open_low else '['}{fmt(low)}, {fmt(high)}]"
    if low is not None:
        return f"{what} {'>' if opt.open_low else '>='} {fmt(low)}"
    return what if high is None else f"{what} <= {fmt(high)}"


def segment_json(segment, i: int, source: str = "timeline") -> dict:
    """Timeline segment ``i``, given as an object or a ``[prompt, seconds]`` pair, as an object (its fields
    are checked by kinema.pipeline.timeline.parse_timeline); anything else is a one-line error."""
    if isinstance(segment, Mapping):
        return dict(segment)
    if not isinstance(segment, list | tuple) or len(segment) != 2:
        raise KinemaError(f"{source}: segment {i}: expected an object with 'prompt' and 'seconds' (or a "
                          f"[prompt, seconds] pair), got {reprlib.repr(segment)}")
    return {"prompt": segment[0], "seconds": segment[1]}


def _number(name: str, value: Any, opt: Option, bounds: RequestBounds, integer: bool) -> None:
    kinds = (int,) if integer else (int, float)
    low, high = opt.low, opt.high_value(bounds)
    ok = isinstance(value, kinds) and is_finite_real(value)
    ok = ok and (low is None or (value > low if opt.open_low else value >= low)) and (high is None or value <= high)
    if not ok:
        raise KinemaError(f"{name}: expected {_range(opt, bounds, integer)}, got {reprlib.repr(value)}")


def _check_field(name: str, value: Any, opt: Option, bounds: RequestBounds) -> None:
    if opt.objects and not isinstance(value, str | int | float | list | tuple | dict):
        return
    if opt.kind in ("int", "float"):
        _number(name, value, opt, bounds, opt.kind == "int")
    elif opt.kind == "bool":
        if not isinstance(value, bool):
            raise KinemaError(f"{name}: expected true or false, got {value!r}")
    elif opt.kind == "pair":
        if not isinstance(value, tuple | list) or len(value) != 2:
            raise KinemaError(f"{name}: expected two numbers, got {value!r}")
        for v in value:
            _number(name, v, opt, bounds, False)
    elif opt.kind == "str":
        if not isinstance(value, str):
            raise KinemaError(f"{name}: expected a string, got {type(value).__name__}")
        high = opt.high_value(bounds)
        if high is not None and len(value) > high:
            raise KinemaError(f"{name}: at most {high:g} characters, got {len(value)}")
        if opt.choices is not None and value.lower() not in opt.choices:
            raise KinemaError(f"{name}: expected one of {', '.join(opt.choices)}, got {value!r}")


def check(request: GenerationRequest, bounds: RequestBounds | None = None) -> None:
    """Raise a one-line `KinemaError` for a field of the wrong type or out of ``bounds`` (default:
    `request_bounds`)."""
    bounds = bounds or request_bounds()
    for f, opt in options(type(request)):
        value = getattr(request, f.name)
        if value is not None:
            _check_field(f.name, value, opt, bounds)
    if request.timeline is not None and request.seconds is not None:
        raise KinemaError("seconds: it is for a prompt; timeline segments carry their own seconds")
    if request.timeline is not None and request.prompt:
        raise KinemaError("give either a prompt or a timeline, not both")
    if request.format == "csv" and request.robot is None:
        raise KinemaError("format: csv is a robot's joint angles; name a robot (robot) or choose bvh, npz or glb")
    if request.robot_mapping is not None and request.robot is None:
        raise KinemaError("robot_mapping: it names a robot's bodies; give the robot too")
    if isinstance(request.timeline, list | tuple):
        total = request.total_seconds()
        if total > bounds.max_seconds + 1e-9:
            raise KinemaError(f"timeline: the motion would last {total:g} s; at most {bounds.max_seconds:g} s")
