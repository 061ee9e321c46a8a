"""Request and response bodies of the HTTP API, as pydantic models that reject unknown keys.

Why a factory: the request limits (seconds, samples, steps, prompt length, ...) are server settings
(kinema.server.config), and putting them into the models puts them into the OpenAPI document too, so a
client (or schemathesis) sees the same bounds the server enforces. `build_request_model` makes the
generate-request class for one `ServerLimits`; everything else is static.

Constraints are kinema's JSON constraint objects (docs/constraints.md), typed key by key here; kinema's
own loader then checks shapes, joints and frames against the model. One difference from constraint
files: a fullbody ``bvh`` must be the BVH text itself (inline), never a file name, since a request must
not make the server read its own files.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from pydantic import BaseModel, BeforeValidator, Field, StrictBool, StrictInt, field_validator, model_validator
from pydantic.json_schema import SkipJsonSchema

from kinema.errors import KinemaError
from kinema.pipeline.request import GenerationRequest, RequestBounds
from kinema.pipeline.request_json import Segment, Strict, number_only, request_model, to_request
from kinema.server.config import ServerLimits

Finite = Annotated[float, Field(allow_inf_nan=False)]
PositiveFinite = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Vec = list[Finite]
Mat = list[list[Finite]]
Cube = list[list[list[Finite]]]
ConstraintType = Literal["fullbody", "end-effector", "left-hand", "right-hand", "left-foot", "right-foot", "root2d",
                         "foot-contact"]
Format = Literal["bvh", "npz", "glb", "json", "csv"]
#: Output formats named in requests that kinema cannot write yet (a clear 422 instead of a bare enum error).
NOT_YET_FORMATS = {"gltf": "glTF (text) export is not implemented in kinema; choose glb, bvh, npz or json"}


class ConstraintSpec(Strict):
    """One kinema constraint object (docs/constraints.md); which keys apply depends on ``type``."""

    type: ConstraintType
    frame_indices: list[StrictInt] | None = None
    times: list[Finite] | None = None
    comment: str | None = None
    local_joints_rot: Cube | None = None
    local_rotations: Cube | None = None
    root_positions: Mat | None = None
    smooth_root_2d: Mat | None = None
    joint: str | None = None
    joint_names: list[str] | None = None
    positions: Mat | None = None
    rotations: Mat | None = None
    global_root_heading: Mat | None = None
    heading: Mat | None = None
    dense: StrictBool | None = None
    contacts: list[list[StrictBool | Finite]] | None = None
    foot_contacts: list[list[StrictBool | Finite]] | None = None
    bvh: str | None = Field(None, description="fullbody only: the BVH file's text (starting with HIERARCHY); "
                                              "file names are rejected")
    source_frames: list[StrictInt] | None = None
    source_times: list[Finite] | None = None
    scale: PositiveFinite | None = None
    recenter: StrictBool | None = None

    @field_validator("bvh")
    @classmethod
    def _inline_bvh_only(cls, value: str | None) -> str | None:
        """Only inline BVH text: a file name would make the server read one of its own files."""
        if value is not None and not value.lstrip().startswith("HIERARCHY"):
            raise ValueError("must be the BVH text itself (starting with HIERARCHY); the server never reads "
                             "files by name, so upload the file's content here")
        return value

    def to_kinema(self) -> dict:
        """The object as kinema's constraint loader reads it (keys that were not given left out)."""
        return self.model_dump(exclude_unset=True, exclude_none=True)


class InlineRig(Strict):
    """A character sent with the request: a GLB (base64) or a BVH (its text)."""

    format: Literal["glb", "bvh"]
    data: Annotated[str, Field(min_length=1, description="base64 of the .glb file, or the BVH text itself")]


class GenerateRequestBase(Strict):
    """The checks across fields of a generate request; `build_request_model` adds the fields, derived from
    kinema's `GenerationRequest` with the bounds of ``limits``."""

    limits: ClassVar[ServerLimits] = ServerLimits()

    @field_validator("format", mode="before", check_fields=False)
    @classmethod
    def _known_format(cls, value: Any) -> Any:
        if isinstance(value, str) and value.lower() in NOT_YET_FORMATS:
            raise ValueError(NOT_YET_FORMATS[value.lower()])
        return value

    @field_validator("objectives", mode="before", check_fields=False)
    @classmethod
    def _no_objectives(cls, value: Any) -> Any:
        raise ValueError("'objectives' are not supported by this server yet; use 'constraints'")

    @model_validator(mode="after")
    def _prompt_xor_timeline(self):
        if (self.prompt is None) == (self.timeline is None):
            raise ValueError("give exactly one of 'prompt' and 'timeline'")
        if self.timeline is not None and self.seconds is not None:
            raise ValueError("'seconds' is for a prompt; timeline segments carry their own seconds")
        total, limit = self.total_seconds(), self.limits.max_seconds
        if total > limit + 1e-9:
            raise ValueError(f"the timeline lasts {total:g} s; this server's limit is {limit:g} s")
        return self

    def total_seconds(self) -> float:
        """The output's duration: the prompt's seconds (or the default) or the segments added up."""
        if self.timeline is not None:
            return float(sum(s.seconds for s in self.timeline))
        return float(self.seconds if self.seconds is not None else min(5.0, self.limits.max_seconds))

    def to_request(self) -> GenerationRequest:
        """kinema's request for this body: the prompt always as a timeline list (kinema would read a prompt
        ending in ``.json`` as a file name), constraints as parsed JSON, an inline rig left to `run`."""
        timeline = ([{"prompt": s.prompt, "seconds": s.seconds} for s in self.timeline] if self.timeline is not None
                    else [{"prompt": self.prompt, "seconds": self.total_seconds()}])
        constraints = [c.to_kinema() for c in self.constraints] if self.constraints else None
        if self.robot is not None and self.format not in ("csv", "npz"):
            raise KinemaError("format: a robot's motion is csv or npz")
        return to_request(self, prompt="", seconds=None, timeline=timeline, constraints=constraints, rig=None,
                          format=self.format)


def build_request_model(limits: ServerLimits, cls: type = GenerationRequest) -> type[GenerateRequestBase]:
    """The ``POST /v1/generate`` (and ``/v1/jobs``) body for these limits: every field of ``cls``
    (kinema.pipeline.request_json), with the server's own shapes for the fields below."""
    bounds = RequestBounds(max_seconds=limits.max_seconds, max_samples=limits.max_samples,
                           max_steps=limits.max_steps, max_prompt_chars=limits.max_prompt_chars)
    prompt_t = Annotated[str, Field(max_length=limits.max_prompt_chars)]
    seconds_t = Annotated[float, BeforeValidator(number_only), Field(gt=0, le=limits.max_seconds, allow_inf_nan=False)]
    these_limits = limits  # a class body cannot read an enclosing name it also assigns

    class LimitedSegment(Segment):
        prompt: prompt_t
        seconds: seconds_t

    class Limited(GenerateRequestBase):
        limits: ClassVar[ServerLimits] = these_limits

    overrides = {
        "prompt": (prompt_t | None, Field(None, description='what the character does ("" = no text)')),
        "seconds": (seconds_t | None, Field(None, description=f"duration for a prompt (default "
                                                             f"{min(5.0, limits.max_seconds):g})")),
        "timeline": Annotated[list[LimitedSegment], Field(min_length=1, max_length=limits.max_segments)],
        "constraints": (Annotated[list[ConstraintSpec], Field(max_length=limits.max_constraints)] | None,
                        Field(None, description="kinema constraint objects, inline (docs/constraints.md)")),
        "objectives": (SkipJsonSchema[Any], Field(None, exclude=True)),
        "keyjoint_model": (Literal["default", "none"] | None,
                           Field(None, description="'default': plan pelvis, head, hands and feet first; 'none': "
                                                   "never; unset: 'default' for sparse joint targets alone")),
        "rig": (Annotated[str, Field(max_length=200)] | InlineRig | None,
                Field(None, description="a rig id from GET /v1/models, or a character inline {format, data}")),
        "format": (Format, Field("bvh", description="bvh (text), npz or glb (base64), json (arrays); with a robot "
                                                   "csv (text) or npz")),
        "robot": (Annotated[str, Field(pattern=r"^[A-Za-z0-9_-]{1,40}$")] | None,
                  Field(None, description="a built-in robot by name ('g1' or 'h1'); the server reads no MJCF files")),
        "robot_mapping": (dict[str, Any] | None, Field(None, description="the robot's bodies as human joints, inline")),
    }
    extra = {"model": (str | None, Field(None, max_length=200, description="a name from GET /v1/models "
                                                                          "(default: the first)"))}
    return request_model("GenerateRequest", cls=cls, bounds=bounds, overrides=overrides, extra=extra, base=Limited)


# ----------------------------------------------------------------------------- responses
class ErrorItem(BaseModel):
    """One validation problem: ``loc`` as FastAPI gives it, ``path`` as a JSONPath (``$.constraints[0].bvh``)."""

    loc: list[str | int]
    path: str
    msg: str
    type: str


class ValidationErrorOut(BaseModel):
    """Body of every 422 answer."""

    detail: list[ErrorItem]


class ErrorOut(BaseModel):
    """Body of the other error answers (401, 404, 409, 413, 429, 504)."""

    detail: str


class MotionOut(BaseModel):
    """One generated motion: BVH text, base64 npz, or a JSON object of arrays (``format``)."""

    index: int
    format: Format
    encoding: Literal["text", "base64", "json"]
    filename: str
    frames: int
    fps: float
    data: str | dict[str, Any]


class ReportOut(BaseModel):
    """kinema's GenerationReport (kinema.pipeline.result): settings, timing, per-sample constraint residuals
    and warnings; the any-rig fields (windows, joints, residuals in cm/deg) are those of any pipeline."""

    seconds: float
    segments: int
    frames: int
    steps: int
    guidance: tuple[float, float]
    #: "separated" (the two weights apply on their own) or "regular" (w_text on text and constraints together)
    guidance_mode: str = ""
    seed: int
    residuals: list[dict[str, Any]]
    warnings: list[str]
    #: per distinct prompt: its nearest training captions and whether it counts as known (issue 18)
    prompts: list[dict[str, Any]] = []
    timings: dict[str, float] = {}
    left_out: list[str] = []
    character: list[dict[str, Any]] = []
    robot: list[dict[str, Any]] = []
    windows: int = 1
    joints: int = 0
    residuals_cm: list[float] = []
    residuals_deg: list[float] = []


class GenerateResponse(BaseModel):
    """The answer of ``POST /v1/generate`` and of ``GET /v1/jobs/{id}/result``."""

    model: str
    rig: str
    format: Format
    motions: list[MotionOut]
    report: ReportOut


class JobOut(BaseModel):
    """A job's state; ``result`` and ``motions`` are the download links once it is ``done``."""

    id: str
    status: Literal["queued", "running", "done", "failed"]
    created: float
    started: float | None = None
    finished: float | None = None
    expires: float | None = None
    error: list[ErrorItem] | str | None = None
    result: str | None = None
    motions: list[str] = []


class RigOut(BaseModel):
    name: str
    joints: list[str]
    parents: list[int]
    fps: float


class ModelOut(BaseModel):
    """A served model, its rigs and the limits that apply to it. ``rig`` is the skeleton a model drives of
    its own (None for a model for any rig: ``needs_rig``, name one of ``rigs`` or send one inline)."""

    name: str
    rig: RigOut | None
    rigs: list[RigOut]
    needs_rig: bool
    text_encoder: str
    sha256: str
    window_seconds: float
    default_steps: int
    limits: dict[str, float | int]


class ModelsOut(BaseModel):
    models: list[ModelOut]
    formats: list[str]
    limits: dict[str, float | int]


class HealthOut(BaseModel):
    status: Literal["ok"]
    models: list[str]
    pending: int
    capacity: int
    jobs: int
