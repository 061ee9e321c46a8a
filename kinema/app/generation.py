"""What the app asks of a model, through the one pipeline interface (kinema.pipeline): a model with its
own skeleton (the human model) generates on it, a model for any rig (``--model creatures``) on the app's
rig; what a model cannot take is named in a note (the report's ``left_out``).

`outcome` runs one generation and returns the motions with the status text and warnings, so that the
session does not care which kind generated them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kinema.app.rigs import AppRig
from kinema.motion.core import Motion
from kinema.pipeline.progress import ProgressFn
from kinema.pipeline.request import GenerationRequest


@dataclass
class Outcome:
    motions: list[Motion]
    text: str
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # what the app left out (said in a notification)


def is_any_rig(model) -> bool:
    """Whether the model generates for the rig the app shows (it drives no skeleton of its own)."""
    return bool(model.needs_rig)


def default_steps(model) -> int:
    return model.default_steps


def max_steps(model) -> int:
    return model.max_steps


def cannot_generate(model, rig: AppRig, model_name: str) -> str | None:
    """Why ``model`` cannot generate for ``rig`` (None when it can)."""
    if is_any_rig(model) or rig.skeleton.same_topology(model.skeleton):
        return None
    return (
        f"the {model_name!r} model generates for its own {model.skeleton.num_joints}-joint skeleton, not "
        f"{rig.name} ({rig.skeleton.num_joints} joints). Press 'Use the model's skeleton' (Rig panel), or run "
        "kinema app --model creatures --rig FILE for any rig."
    )


def outcome(
    model, rig: AppRig, timeline: list[dict], *, constraints, samples: int, steps: int, seed: int, progress: ProgressFn
) -> Outcome:
    """Generate ``samples`` motions for ``timeline`` and ``constraints`` (docs/constraints.md, world frame)
    on the app's rig: one `GenerationRequest` for any model (kinema.pipeline)."""
    any_rig = is_any_rig(model)
    request = GenerationRequest(timeline=timeline, constraints=list(constraints) if constraints else None,
                                samples=samples, steps=steps, seed=seed, rig=rig.skeleton if any_rig else None)
    res = model.generate(request, progress=progress)
    r = res.report
    motions = [rig.with_contacts(m) for m in res.motions] if any_rig else list(res.motions)
    on = f" on {rig.name}" if any_rig else ""
    text = (f"{len(motions)} sample(s){on}, {motions[0].num_frames} frames, {r.segments} segment(s), {r.steps} steps, "
            f"seed {r.seed}: **{r.seconds:.1f} s**")
    if r.residuals_cm:
        text += f"; joint targets met within {max(r.residuals_cm):.1f} cm"
    return Outcome(motions, text, list(r.warnings), list(r.left_out))
