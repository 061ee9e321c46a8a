"""What a generation call returns: `GenerationResult` (the motions, indexable like a list) and its
`GenerationReport`, one report type for every pipeline.

Fields a pipeline has nothing to say about keep their defaults: the human model runs no windows and
translates no bones; the any-rig model grounds no prompts. Lengths are metres, residuals centimetres
(``residuals_cm``) and degrees (``residuals_deg``) measured on the final output.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from kinema.motion.core import Motion
from kinema.pipeline import stages
from kinema.pipeline.stages import load_stage


@dataclass
class GenerationReport:
    """What one ``generate`` call did.

    Common to every pipeline: ``seconds`` (wall time), ``steps``, ``seed``, ``guidance`` (the weights) and
    ``guidance_mode`` (kinema.diffusion.guidance: "separated" or "regular"; a call without constraints runs
    the two-branch regular form either way), ``segments``,
    ``frames``, ``warnings`` (what a user must hear: unmet targets, unknown prompts, stages undone by the
    guard), ``left_out`` (parts of the request the model cannot take and left out, e.g. foot contacts for
    the any-rig model), ``timings`` (wall seconds per stage).

    The human pipeline (kinema.human): ``residuals`` holds one post-processing report per sample (empty
    dicts without post-processing: ``{"smooth", "foot_lock", "exact": {"before", "after", ...},
    "plausibility", "warnings"}``), ``prompts`` per distinct prompt its nearest training captions and what
    grounding did (kinema.model.vocabulary, kinema.model.grounding), ``objectives`` the noise-optimised
    objectives' values.

    The any-rig pipeline (kinema.anyrig): ``windows``, ``joints``, ``root_stage`` (whether the model's root
    stage sampled the root first, kinema.model.anyrig.root_stage), ``residuals_cm`` / ``residuals_deg``
    (constraint errors after post-processing), ``foot_lock``, the largest vertical change of de-jittering
    the root height, of putting the motion on the floor and of settling the body onto its legs (rig sizes:
    ``height_smoothed``, ``grounded``, ``settled``) and ``reached_by_translation`` (joint targets met by
    translating a bone: name -> largest shift, rig sizes).

    A request whose rig is the user's character (for a model with a skeleton of its own): ``character``
    holds per sample the retargeting measurements (kinema.retarget.quality: scale, direction error, bone
    drift, lowest joint vs rest, foot skate of source and character) and ``targets_cm``, the character's
    own end-effector targets measured on the final output; ``residuals`` stay the model's own, before
    retargeting. A request that names a robot: ``robot`` holds per sample the replay measurements of its robot motion
    (kinema.robot.stage: range overshoot, lowest sole, planted-sole slide, travel, leg overlap).
    """

    seconds: float = 0.0
    segments: int = 1
    frames: int = 0
    steps: int = 0
    guidance: tuple[float, float] = (0.0, 0.0)
    guidance_mode: str = ""
    seed: int = 0
    warnings: list[str] = field(default_factory=list)
    left_out: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    residuals: list[dict] = field(default_factory=list)
    prompts: list[dict] = field(default_factory=list)
    objectives: dict = field(default_factory=dict)
    windows: int = 1
    joints: int = 0
    root_stage: bool = False
    residuals_cm: list[float] = field(default_factory=list)
    residuals_deg: list[float] = field(default_factory=list)
    foot_lock: list[dict] = field(default_factory=list)
    grounded: float = 0.0
    height_smoothed: float = 0.0
    settled: float = 0.0
    reached_by_translation: dict[str, float] = field(default_factory=dict)
    robot: list[dict] = field(default_factory=list)
    character: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        """The report as strict JSON values (what the server answers and batch manifests record)."""
        return json_safe(asdict(self))


class GenerationResult(Sequence):
    """The motions of one call (indexable like a list) and that call's own report; ``robot_motions``:
    the same motions on the robot the request named (kinema.robot.RobotMotion), else empty."""

    def __init__(self, motions: list[Motion], report: GenerationReport, robot_motions: list | None = None) -> None:
        self.motions, self.report = list(motions), report
        self.robot_motions = list(robot_motions or [])

    def __getitem__(self, index):
        return self.motions[index]

    def __len__(self) -> int:
        return len(self.motions)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({len(self.motions)} motion(s), {self.report.seconds:.2f} s)"

    def retarget(self, character) -> GenerationResult:
        """The motions on a humanoid ``character`` (a GLB, BVH, FBX or npz file; kinema.retarget), with
        the retargeting measurements in ``report.character``; this result is left as it is."""
        stage = load_stage(stages.CHARACTER).open(character, self.motions[0].skeleton)
        motions, measured, warnings = stage.finish(self.motions, None, self.motions[0].fps)
        report = replace(self.report, character=measured, warnings=[*self.report.warnings, *warnings])
        return GenerationResult(motions, report, self.robot_motions)


def json_safe(value):
    """``value`` with tensors/arrays as lists, numpy scalars as Python numbers and non-finite floats as None."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        value = float(value)
        return value if math.isfinite(value) else None
    return str(value)
