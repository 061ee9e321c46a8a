"""`MotionPipeline`: the one interface every generation model implements.

``load_model`` (kinema.generate) returns one; faces (CLI, server, batch, app, streaming) call
``generate(request)`` and read the few properties below, and never ask which model it is. A request
field a pipeline cannot honour is a one-line `KinemaError` from that pipeline ("the any-rig model keeps
no training captions to ground prompts on"), never silently ignored.

``generate`` also takes the request's fields as keywords (``model.generate("A person walks.",
seconds=4)``), the short form for Python callers; both forms build the same `GenerationRequest`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from kinema.errors import KinemaError
from kinema.input_files import check_input_file
from kinema.pipeline import stages
from kinema.pipeline.progress import ProgressFn
from kinema.pipeline.request import GenerationRequest
from kinema.pipeline.result import GenerationResult
from kinema.pipeline.stages import load_stage
from kinema.stream import MotionStream, open_stream


@dataclass(frozen=True)
class RigInfo:
    """A rig a model drives without a file: its id, joint names and parents (for ``GET /v1/models``)."""

    name: str
    joints: list[str]
    parents: list[int]
    files: list[str]


def request_from_keywords(what: Any = None, **keywords) -> GenerationRequest:
    """The request of ``generate(what, **keywords)``: ``what`` is a prompt, a timeline (a list of
    ``{"prompt", "seconds"}`` / ``(prompt, seconds)`` segments, or a .json file path) or None."""
    if isinstance(what, str) and not what.lower().endswith(".json"):
        keywords["prompt"] = what
    elif what is not None:
        keywords.pop("seconds", None)  # a timeline's segments carry their own seconds (the keyword is ignored)
        keywords["timeline"] = what
    grounding = keywords.get("grounding")
    if grounding is not None and not isinstance(grounding, int | float) or isinstance(grounding, bool):
        keywords.update(_grounding_fields(keywords.pop("grounding")))
    if isinstance(keywords.get("guidance"), list):
        keywords["guidance"] = tuple(keywords["guidance"])
    try:
        return GenerationRequest(**keywords)
    except TypeError as err:  # an unknown keyword
        raise KinemaError(f"generate: {err}") from None


def _grounding_fields(value: Any) -> dict:
    """A ``Grounding``, its dict, or a bool as the request's grounding fields."""
    if isinstance(value, bool):
        return {} if value else {"grounding": 0.0}
    data = value.to_dict() if hasattr(value, "to_dict") else value
    if not isinstance(data, Mapping):
        raise KinemaError(f"grounding: expected a weight in [0, 1], a Grounding or its dict, got {value!r}")
    names = {"weight": "grounding", "top_k": "grounding_top_k", "temperature": "grounding_temperature"}
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise KinemaError(f"grounding: unknown key {unknown[0]!r} (expected weight, top_k, temperature)")
    return {names[k]: v for k, v in data.items()}


class MotionPipeline(ABC):
    """A loaded model that turns a `GenerationRequest` into a `GenerationResult`."""

    #: the value of ``checkpoint.json``'s "pipeline" key that names this class
    pipeline_name: ClassVar[str]
    #: seconds of a single prompt when the request gives none
    default_seconds: ClassVar[float] = 5.0
    #: True when a request must name a rig (the model drives no skeleton of its own)
    needs_rig: ClassVar[bool] = False
    #: inference precisions ``load`` takes as ``precision=`` (kinema.model.precision); fp32 is never passed
    precisions: ClassVar[tuple[str, ...]] = ("fp32",)

    @classmethod
    @abstractmethod
    def load(cls, ckpt: Path, text_encoder_for) -> MotionPipeline:
        """The pipeline of a checkpoint folder; ``text_encoder_for(encoder_id)`` makes the text encoder its
        checkpoint names (called once the checkpoint has been read and checked)."""

    # ------------------------------------------------------------------ what faces read
    #: the loaded checkpoint: its network and settings (``path``, ``fps``, ``text_encoder_id``, ``sampler``)
    loaded: Any

    @property
    def path(self) -> Path:
        """The checkpoint folder."""
        return self.loaded.path

    @property
    def fps(self) -> float:
        return self.loaded.fps

    @property
    def text_encoder_id(self) -> str:
        return self.loaded.text_encoder_id

    @property
    def max_steps(self) -> int:
        """The largest number of DDIM steps (the training noise schedule's length)."""
        return self.loaded.sampler.num_train_steps

    @property
    def default_steps(self) -> int:
        return self.loaded.sampler.num_inference_steps

    @property
    @abstractmethod
    def window_seconds(self) -> float:
        """The longest stretch the denoiser sees at once (longer motions are made of several)."""

    def window_for(self, prompt: str) -> float | None:
        """The longest stretch (s) this model makes ``prompt`` in at once, where it knows one (the human model:
        from how long the prompt's action was captured, kinema.human.continuation); None = `window_seconds`."""
        return None

    @abstractmethod
    def rigs(self) -> list[RigInfo]:
        """The rigs this model drives without a rig file (the human model: its own skeleton)."""

    @abstractmethod
    def resolve_rig(self, rig):
        """The `Rig` a request's ``rig`` names (a file path, a rig id, a `Skeleton` or `Rig`), in metres."""

    # ------------------------------------------------------------------ generation
    def generate(self, request: GenerationRequest | Any = None, /, *, progress: bool | ProgressFn = False,
                 **keywords) -> GenerationResult:
        """Generate what ``request`` asks (or a request built from a prompt/timeline and keywords).

        ``progress``: True shows a bar; a callable ``fn(done, total)`` is called with the denoiser steps
        done so far; it never changes the result.
        """
        if isinstance(request, GenerationRequest):
            if keywords:
                request = request.replace(**keywords)
        else:
            request = request_from_keywords(request, **keywords)
        character = self._character(request)
        robot = None if request.robot is None else load_stage(stages.ROBOT_DESCRIPTION)(request.robot,
                                                                                        request.robot_mapping)
        if character is None:
            result = self.run(request, progress=progress)
        else:
            model_request = request.replace(rig=None, constraints=character.model_constraints(request.constraints))
            result = self.run(model_request, progress=progress)
        model_motions = result.motions
        if character is not None:
            result.motions, result.report.character, unmet = character.finish(model_motions, request.constraints,
                                                                              self.fps)
            result.report.warnings += unmet
        if robot is not None:
            result.robot_motions, result.report.robot = load_stage(stages.ROBOT)(model_motions, robot)
            result.report.warnings += [m["warning"] for m in result.report.robot if m["warning"]]
        return result

    def _character(self, request: GenerationRequest):
        """The character stage (kinema.retarget.stage) when the request's rig is a character this model
        does not drive itself: a humanoid file for a model with a skeleton of its own; else None."""
        rig = request.rig
        if rig is None or self.needs_rig or not isinstance(rig, str | Path):
            return None
        if str(rig) in {r.name for r in self.rigs()} or not (Path(rig).suffix or Path(rig).exists()):
            return None  # its own rig, or a rig id it does not drive: the pipeline says what it drives
        check_input_file(rig, "rig file")
        return load_stage(stages.CHARACTER).open(rig, self.resolve_rig(None).skeleton)

    def stream(self, request: GenerationRequest | None = None, **options) -> MotionStream:
        """An endless live motion of this model, window by window, following prompt, steering and target
        commands while it plays (kinema.stream.open_stream, docs/stream.md)."""
        return open_stream(self, request, **options)

    @abstractmethod
    def run(self, request: GenerationRequest, *, progress: bool | ProgressFn = False) -> GenerationResult:
        """Generate what ``request`` asks; see `generate`."""
