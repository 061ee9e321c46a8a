"""What the app asks of a model, for both kinds kinema has: the human model (`KinemaModel`: its own
skeleton, timelines, the constraints of docs/constraints.md, step progress) and the any-rig model
(`AnyRigModel`, ``--model creatures``: any rig, one prompt, the constraints kinema.app.anyrig_bridge
translates; the rest are named in a note).

`outcome` runs one generation and returns the motions with the status text and warnings, so that the
session does not care which kind generated them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kinema.app.anyrig_bridge import to_anyrig
from kinema.app.rigs import AppRig
from kinema.generate.anyrig_api import AnyRigModel
from kinema.generate.anyrig_constraints import JointTarget
from kinema.generate.progress import ProgressFn
from kinema.motion.core import Motion


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
    seconds = sum(float(s["seconds"]) for s in timeline)
    notes = []
    if len(timeline) > 1:
        notes.append(f"the any-rig model takes one prompt: {timeline[0]['prompt']!r} for {seconds:g} s")
    constraints = list(constraints or [])
    cons, left = to_anyrig(constraints, rig.skeleton, model.fps)
    notes += left
    prompt, args = timeline[0]["prompt"], dict(rig=rig.skeleton, seconds=seconds, steps=steps, seed=seed)
    took, passes = 0.0, 1 + any(isinstance(c, JointTarget) for c in cons)
    if passes == 2:
        # joint targets are taken in the character frame: read the world targets in that of a first, raw
        # pass without them (the same seed puts the body there again), then generate with them
        first = model.generate(
            prompt,
            constraints=[c for c in cons if not isinstance(c, JointTarget)],
            samples=1,
            postprocess=False,
            progress=_pass_progress(progress, 0, passes),
            **args,
        )
        cons, _ = to_anyrig(constraints, rig.skeleton, model.fps, reference=first.motions[0])
        took = first.report.seconds
    res = model.generate(
        prompt, constraints=cons, samples=samples, progress=_pass_progress(progress, passes - 1, passes), **args
    )
    r = res.report
    motions = [rig.with_contacts(m) for m in res.motions]
    text = (
        f"{len(motions)} sample(s) on {rig.name}, {motions[0].num_frames} frames, {r.steps} steps, seed {seed}: "
        f"**{took + r.seconds:.1f} s**"
    )
    if r.residuals_cm:
        text += f"; joint targets met within {max(r.residuals_cm):.1f} cm"
    return Outcome(motions, text, list(r.warnings), notes)


def _pass_progress(progress: ProgressFn | None, k: int, passes: int) -> ProgressFn | None:
    """``progress`` for pass ``k`` of ``passes`` (one bar over all of them)."""
    if progress is None:
        return None
    return lambda done, total: progress(k * total + done, passes * total)
