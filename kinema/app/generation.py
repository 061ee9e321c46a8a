"""What the app asks of a model, through the one pipeline interface (kinema.pipeline): a model with its
own skeleton (the human model) generates on it, a model for any rig (``--model creatures``) on the app's
rig; what a model cannot take is named in a note (the report's ``left_out``).

A humanoid character shown with the human model (a GLB/BVH/FBX rig, kinema.retarget) is handed to the
pipeline as its file: the motion is generated on the model's skeleton and retargeted onto the character,
so its skin plays it. With ``kinema app --robot g1`` every request also names the robot, and each
sample's robot motion comes back drawn as a kinema Motion of the robot's body frames (kinema.robot.drawing).

`outcome` runs one generation and returns the motions with the status text and warnings, so that the
session does not care which kind generated them. A progress callback that raises `Cancelled` stops a
generation between denoiser steps (the pipelines call it after every step).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from kinema.app.rigs import AppRig
from kinema.motion.core import Motion
from kinema.pipeline.progress import ProgressFn
from kinema.pipeline.request import GenerationRequest
from kinema.robot.drawing import robot_motion_for_drawing


class Cancelled(Exception):
    """Raised by the app's progress callback to stop a generation (Cancel pressed, or the tab closed)."""


@dataclass
class Outcome:
    motions: list[Motion]
    text: str
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # what the app left out (said in a notification)
    robot_motions: list[Motion] = field(default_factory=list)  # per sample, the robot's body frames (drawn)


@dataclass(frozen=True)
class AppRobot:
    """The robot shown beside each sample: what requests name (``"g1"`` or an MJCF path), its description and
    the mapping file that names its bodies (None: names recognised)."""

    spec: str
    description: object  # kinema.robot.description.Robot
    mapping: Path | None = None


def is_any_rig(model) -> bool:
    """Whether the model generates for the rig the app shows (it drives no skeleton of its own)."""
    return bool(model.needs_rig)


def default_steps(model) -> int:
    return model.default_steps


def max_steps(model) -> int:
    return model.max_steps


def is_character(model, rig: AppRig) -> bool:
    """Whether ``rig`` is a humanoid character the model (with a skeleton of its own) retargets onto."""
    return not is_any_rig(model) and not rig.skeleton.same_topology(model.skeleton) and rig.humanoid


def cannot_generate(model, rig: AppRig, model_name: str) -> str | None:
    """Why ``model`` cannot generate for ``rig`` (None when it can)."""
    if is_any_rig(model) or rig.skeleton.same_topology(model.skeleton) or is_character(model, rig):
        return None
    return (
        f"the {model_name!r} model generates for its own {model.skeleton.num_joints}-joint skeleton and retargets "
        f"onto humanoid characters; {rig.name} ({rig.skeleton.num_joints} joints) is not one (no legs, arms and "
        "head found by name). Press 'Use the model's skeleton' (Rig panel), or run kinema app --model creatures "
        "--rig FILE for any rig."
    )


def outcome(model, rig: AppRig, timeline: list[dict], *, constraints, samples: int, steps: int, seed: int,
            progress: ProgressFn, robot: AppRobot | None = None) -> Outcome:
    """Generate ``samples`` motions for ``timeline`` and ``constraints`` (docs/constraints.md, world frame)
    on the app's rig: one `GenerationRequest` for any model (kinema.pipeline). ``robot``: the robot every
    sample is retargeted onto as well (drawn beside it)."""
    request = GenerationRequest(timeline=timeline, constraints=list(constraints) if constraints else None,
                                samples=samples, steps=steps, seed=seed,
                                rig=rig.skeleton if is_any_rig(model) else None,
                                robot=None if robot is None else robot.spec,
                                robot_mapping=None if robot is None else robot.mapping)
    if is_character(model, rig):
        with tempfile.TemporaryDirectory(prefix="kinema-app-character-") as tmp:
            path = Path(tmp) / rig.name
            path.write_bytes(rig.source)
            res = model.generate(request.replace(rig=str(path)), progress=progress)
    else:
        res = model.generate(request, progress=progress)
    return _outcome(model, rig, res, robot)


def _outcome(model, rig: AppRig, res, robot) -> Outcome:
    r = res.report
    drawn = is_any_rig(model) or is_character(model, rig)
    motions = [rig.with_contacts(on_rig(m, rig)) for m in res.motions] if drawn else list(res.motions)
    on = f" on {rig.name}" if drawn else ""
    text = (f"{len(motions)} sample(s){on}, {motions[0].num_frames} frames, {r.segments} segment(s), {r.steps} steps, "
            f"seed {r.seed}: **{r.seconds:.1f} s**")
    if r.residuals_cm:
        text += f"; joint targets met within {max(r.residuals_cm):.1f} cm"
    robots = [robot_motion_for_drawing(m, robot.description) for m in res.robot_motions] if robot else []
    if robots:
        text += f"; beside each, the robot {robot.spec} (blue)" + _robot_words(r.robot)
    return Outcome(motions, text, list(r.warnings), list(r.left_out), robots)


def on_rig(motion: Motion, rig: AppRig) -> Motion:
    """A character's motion on the joints the app shows: the retargeting reads the file's every bone, the
    app's rig leaves out bones no skin follows (IK foot and pole helpers), which are dropped here."""
    names = set(rig.skeleton.names)
    extra = [n for n in motion.skeleton.names if n not in names]
    return motion.prune(extra) if extra else motion


def _robot_words(measures: list[dict]) -> str:
    """The robot replay's worst range overshoot and sole slide, and each sample's inverse dynamics, in words
    (empty when not measured); a sample that is not feasible also has its warning in the outcome's warnings."""
    if not measures:
        return ""
    over = math.degrees(max(float(m.get("range_overshoot_rad", 0.0)) for m in measures))
    slide = max(float(m.get("planted_slide_m_s", 0.0)) for m in measures)
    feasible = sum(bool(m.get("feasible")) for m in measures)
    dynamics = "".join(f"; sample {i} dynamics: {m['dynamics_summary']}" for i, m in enumerate(measures)
                       if "dynamics_summary" in m)
    return (f" (joint range overshoot {over:.1f} deg, planted-sole slide {slide:.2f} m/s; "
            f"{feasible} of {len(measures)} "
            f"feasible in MuJoCo inverse dynamics{dynamics})")
