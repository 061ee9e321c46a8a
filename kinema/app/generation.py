"""What the app asks of a model, for both kinds kinema has: the human model (`KinemaModel`: its own
skeleton, timelines, the constraints of docs/constraints.md, step progress) and the any-rig model
(`AnyRigModel`, ``--model creatures``: any rig, timelines, the constraints kinema.anyrig.world
translates; the rest are named in a note).

`outcome` runs one generation and returns the motions with the status text and warnings, so that the
session does not care which kind generated them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kinema.anyrig.pipeline import AnyRigModel
from kinema.anyrig.world import generate_world
from kinema.app.rigs import AppRig
from kinema.motion.core import Motion
from kinema.pipeline.progress import ProgressFn


@dataclass
class Outcome:
    motions: list[Motion]
    text: str
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # what the app left out (said in a notification)


def is_any_rig(model) -> bool:
    return isinstance(model, AnyRigModel)


def default_steps(model) -> int:
    return model.loaded.sampler.num_inference_steps


def max_steps(model) -> int:
    return model.loaded.sampler.num_train_steps if is_any_rig(model) else model.max_steps


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
    """Generate ``samples`` motions for ``timeline`` (and ``constraints`` with the human model)."""
    if not is_any_rig(model):
        res = model.generate(
            timeline, constraints=constraints, samples=samples, steps=steps, seed=seed, progress=progress
        )
        r = res.report
        text = (
            f"{len(res.motions)} sample(s), {r.frames} frames, {r.segments} segment(s), {r.steps} steps, "
            f"seed {r.seed}: **{r.seconds:.1f} s**"
        )
        return Outcome(list(res.motions), text, list(r.warnings))
    res, notes, took = generate_world(
        model,
        timeline,
        rig=rig.skeleton,
        constraints=list(constraints or []),
        samples=samples,
        steps=steps,
        seed=seed,
        progress=progress,
    )
    r = res.report
    motions = [rig.with_contacts(m) for m in res.motions]
    text = (
        f"{len(motions)} sample(s) on {rig.name}, {motions[0].num_frames} frames, {r.segments} segment(s), "
        f"{r.steps} steps, seed {seed}: **{took:.1f} s**"
    )
    if r.residuals_cm:
        text += f"; joint targets met within {max(r.residuals_cm):.1f} cm"
    return Outcome(motions, text, list(r.warnings), notes)
