"""The models a server (or a batch) serves: loaded once, shared by every worker thread.

Why a registry: `kinema serve --model A --model B=PATH` loads each model once at start-up (a
`KinemaModel` is safe to share between threads), requests name a model and optionally a rig, and
``GET /v1/models`` lists what is there with its limits. `model_sha256` fingerprints a checkpoint
so a batch manifest (and /v1/models) says exactly which weights made a motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from kinema.errors import KinemaError
from kinema.model.fingerprint import model_sha256
from kinema.server.errors import RequestError


def parse_model_spec(spec: str) -> tuple[str, str]:
    """``NAME=PATH`` -> (NAME, PATH); ``default`` -> ("default", "default"); ``PATH`` -> (folder name, PATH)."""
    if "=" in spec:
        name, path = spec.split("=", 1)
        if not name or not path:
            raise KinemaError(f"--model {spec!r}: expected NAME=PATH, 'default' or PATH")
        return name, path
    if spec in ("", "default"):
        return "default", "default"
    return Path(spec).resolve().name or spec, spec


@dataclass
class ServedModel:
    """A loaded model (a kinema `MotionPipeline`) under the name clients use for it."""

    name: str
    model: object  # kinema.pipeline.base.MotionPipeline (imported lazily: torch)
    sha256: str

    @property
    def rig_names(self) -> list[str]:
        return [r.name for r in self.model.rigs()]

    @property
    def rig(self) -> str:
        """The rig a request gets without naming one: the model's own skeleton, or "inline" for a model
        for any rig (its requests name a rig)."""
        return "inline" if self.model.needs_rig else self.rig_names[0]

    def max_steps(self, server_max: int) -> int:
        return min(server_max, self.model.max_steps)

    def info(self, limits: dict) -> dict:
        """``ModelOut`` for ``GET /v1/models``: the rigs, the window and the limits that apply here."""
        fps = float(self.model.fps)
        rigs = [{"name": r.name, "joints": r.joints, "parents": r.parents, "fps": fps} for r in self.model.rigs()]
        return {
            "name": self.name,
            "rig": None if self.model.needs_rig else rigs[0],
            "rigs": rigs,
            "needs_rig": bool(self.model.needs_rig),
            "text_encoder": str(self.model.text_encoder_id),
            "sha256": self.sha256,
            "window_seconds": float(self.model.window_seconds),
            "default_steps": int(self.model.default_steps),
            "limits": limits | {"max_steps": self.max_steps(limits["max_steps"])},
        }

    def drives(self, rig, humanoid: bool = False) -> bool:
        """Whether a request's ``rig`` (None, a rig id, or an inline character; ``humanoid``: that character
        is one) can go to this model: a model for any rig takes any character, a model with a skeleton of
        its own a humanoid one (retargeted onto it, kinema.retarget)."""
        if rig is None:
            return not self.model.needs_rig
        if isinstance(rig, str):
            return rig in self.rig_names
        return bool(self.model.needs_rig) or humanoid


class ModelRegistry:
    """Name -> ServedModel, in the order given (the first is the default)."""

    def __init__(self, served: list[ServedModel]):
        if not served:
            raise KinemaError("no model to serve")
        self.models = {s.name: s for s in served}
        if len(self.models) != len(served):
            raise KinemaError("two --model entries have the same name; use NAME=PATH to tell them apart")

    @classmethod
    def load(cls, specs: list[str]) -> ModelRegistry:
        """Load every ``--model`` spec (see `parse_model_spec`)."""
        from kinema.generate import load_model

        served = []
        for spec in specs or ["default"]:
            name, path = parse_model_spec(spec)
            model = load_model(path)
            served.append(ServedModel(name, model, model_sha256(model.path)))
        return cls(served)

    @property
    def names(self) -> list[str]:
        return list(self.models)

    def resolve(self, name: str | None, rig, humanoid: bool = False) -> ServedModel:
        """The model a request asks for: by name, else the first that drives its rig (a rig id; an inline
        humanoid character: a model with a skeleton of its own first, retargeted; any other character: a
        model for any rig; none: a model with its own skeleton)."""
        if name is not None:
            served = self.models.get(name)
            if served is None:
                raise RequestError.at(["body", "model"], f"unknown model; this server has {self.names}")
            if not served.drives(rig, humanoid=True):
                what = "needs a rig: name one from GET /v1/models or send one inline" if rig is None else (
                    f"does not drive rig {rig!r}; its rigs: {served.rig_names}" if isinstance(rig, str)
                    else f"drives its own skeleton {served.rig!r}, not an inline character")
                raise RequestError.at(["body", "rig"], f"model {name!r} {what}")
            return served
        order = list(self.models.values())
        if humanoid:  # a humanoid character: a model with a skeleton of its own (retargeted) comes first
            order.sort(key=lambda s: bool(s.model.needs_rig))
        for served in order:
            if served.drives(rig, humanoid):
                return served
        rigs = sorted({r for s in self.models.values() for r in s.rig_names})
        raise RequestError.at(["body", "rig"], f"no model here drives this rig; rigs: {rigs}")
