"""The character stage of a generation: the user's humanoid character for a model that drives a skeleton
of its own (the human model).

``MotionPipeline.generate`` (kinema.pipeline.base) imports this module by name when a request's rig is a
character file the model does not drive itself. The request is generated on the model's skeleton with its
constraints read in the model's terms (joint names of the character mapped to the model's, positions
scaled by the body-size ratio), and every motion is retargeted onto the character (kinema.retarget.core).
End-effector targets written for the character are then met on the character itself
(kinema.retarget.targets), and every residual in the report is measured there, on the final output.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import torch

from kinema.constraints.fps import read_constraints_json
from kinema.errors import KinemaError
from kinema.input_files import read_json_bounded
from kinema.motion.core import Motion
from kinema.retarget.character import Character, load_character
from kinema.retarget.core import retarget_with_map
from kinema.retarget.mapping import JointMap, build_joint_map, constraint_joint_names
from kinema.retarget.proportions import body_scale
from kinema.retarget.quality import retarget_report
from kinema.retarget.targets import meet_targets
from kinema.skeleton import Skeleton

#: JSON keys of docs/constraints.md that hold world positions (metres) and so scale with the body
POSITION_KEYS = ("positions", "root_positions", "smooth_root_2d")
#: a target on the character missed by more than this (cm) is a warning
UNMET_CM = 2.0


@dataclass
class CharacterStage:
    """A character and how the model's skeleton maps onto it."""

    character: Character
    joint_map: JointMap
    names: dict[str, str]  # character joint name -> model joint name
    scale: float  # character size / model size (mean leg length)

    @classmethod
    def open(cls, rig, model: Skeleton) -> CharacterStage:
        """The stage for a request's ``rig`` (a GLB, glTF, BVH, FBX or npz character file)."""
        if not isinstance(rig, str | Path):
            raise KinemaError(f"rig: expected a character file (GLB, BVH, FBX), got {type(rig).__name__}")
        character = load_character(rig)
        found = character.humanoid()
        if not found.is_humanoid:
            missing = ", ".join(found.missing[:6]) or "limbs"
            raise KinemaError(f"rig {rig}: not a humanoid ({missing} not found), so the human model cannot drive it; "
                              "use a model for any rig (--model creatures), or name its joints in a rig overrides JSON")
        jm = build_joint_map(model, character.skeleton)
        return cls(character, jm, constraint_joint_names(character.skeleton, model), body_scale(jm))

    # ------------------------------------------------------------------ before generating
    def model_constraints(self, constraints):
        """``constraints`` (docs/constraints.md: a file, a list, or ``{"fps", "constraints"}``) in the model's
        terms: character joint names mapped to the model's, world positions divided by the size ratio."""
        if constraints is None:
            return None
        data = self._json(constraints)
        items = data["constraints"] if isinstance(data, dict) else data
        for obj in items if isinstance(items, list) else []:
            if not isinstance(obj, dict):
                continue
            if isinstance(obj.get("joint"), str):
                obj["joint"] = self.names.get(obj["joint"], obj["joint"])
            if isinstance(obj.get("joint_names"), list):
                obj["joint_names"] = [self.names.get(n, n) if isinstance(n, str) else n for n in obj["joint_names"]]
            for key in POSITION_KEYS:
                if key in obj:
                    obj[key] = _scaled(obj[key], 1.0 / self.scale)
        return data

    @staticmethod
    def _json(constraints):
        """A copy of the constraints as parsed JSON; a file is read (kinema.constraints.fps, its errors) and
        its relative BVH paths made absolute, so they stay usable in the copy."""
        if not isinstance(constraints, str | Path):
            return copy.deepcopy(constraints)
        items, _source, dirs, _fps = read_constraints_json(constraints)
        raw = read_json_bounded(constraints, "constraints file")
        for obj in items:
            if isinstance(obj, dict) and isinstance(obj.get("bvh"), str) and not Path(obj["bvh"]).is_absolute():
                found = next((d / obj["bvh"] for d in dirs if (d / obj["bvh"]).is_file()), None)
                obj["bvh"] = str(found.resolve()) if found is not None else obj["bvh"]
        return {**raw, "constraints": items} if isinstance(raw, dict) else items

    # ------------------------------------------------------------------ after generating
    def finish(self, motions: list[Motion], constraints, fps: float) -> tuple[list[Motion], list[dict], list[str]]:
        """Each motion on the character, its end-effector targets met there, and per motion the retarget
        measurements and the targets' residuals (cm, on the final output); warnings for unmet targets."""
        targets = self._targets(constraints, fps)
        out, reports, warnings = [], [], []
        for i, motion in enumerate(motions):
            moved = retarget_with_map(motion, self.joint_map)
            if targets:
                moved = meet_targets(moved, targets, overrides=self.character.overrides)
            rep = retarget_report(motion, moved, self.joint_map) | {"character": str(self.character.path)}
            rep["targets_cm"] = _residuals(moved, targets)
            for name, err in rep["targets_cm"].items():
                if err > UNMET_CM:
                    warnings.append(f"sample {i}: target on {name} missed by {err:.1f} cm on the character")
            out.append(moved)
            reports.append(rep)
        return out, reports, warnings

    def _targets(self, constraints, fps: float) -> dict[str, dict[int, list[float]]]:
        """{character hand/foot joint: {frame: world position}} of the end-effector constraints that name
        the character's own joints (frames at ``fps``, the output's)."""
        if constraints is None:
            return {}
        data = self._json(constraints)
        items = data["constraints"] if isinstance(data, dict) else data
        source_fps = data.get("fps", fps) if isinstance(data, dict) else fps
        names = set(self.character.skeleton.names)
        out: dict[str, dict[int, list[float]]] = {}
        for obj in items if isinstance(items, list) else []:
            if not isinstance(obj, dict) or obj.get("joint") not in names or "positions" not in obj:
                continue
            frames = obj.get("frame_indices")
            if frames is None and "times" in obj:
                frames = [round(t * fps) for t in obj["times"]]
            else:
                frames = [round(f * fps / source_fps) for f in frames or []]
            out.setdefault(obj["joint"], {}).update(zip(frames, obj["positions"], strict=False))
        return out


def _scaled(value, factor: float):
    """Nested lists of numbers times ``factor``."""
    if isinstance(value, list):
        return [_scaled(v, factor) for v in value]
    return value * factor if isinstance(value, int | float) and not isinstance(value, bool) else value


def _residuals(motion: Motion, targets: dict[str, dict[int, list[float]]]) -> dict[str, float]:
    """Largest distance (cm) of each target joint from its world targets on ``motion``."""
    P = motion.positions
    out = {}
    for name, frames in targets.items():
        j = motion.skeleton.index(name)
        want = torch.tensor([list(v) for v in frames.values()], dtype=P.dtype)
        got = P[[int(f) for f in frames], j]
        out[name] = float(100 * (got - want).norm(dim=-1).max())
    return out
