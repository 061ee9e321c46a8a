"""Generation with objectives: what ``KinemaModel.generate(..., objectives=...)`` runs.

The objectives of a call come from the constraints file's ``"objectives"`` list and the ``objectives``
argument; they are bound to the model's rig and the motion length, the noise of a short DDIM chain is
optimised for them (kinema.human.noise_optimisation) with the file's explicit constraints imputed as usual,
and the report gives every objective's value before optimisation, after it (raw) and on the final,
post-processed motion. Objectives act on one motion of at most the model's ``max_seconds`` (one
segment), not on multi-prompt timelines.
"""

from __future__ import annotations

import os
from dataclasses import replace
from typing import TYPE_CHECKING

import torch

from kinema.errors import KinemaError
from kinema.human.noise_optimisation import NoiseOptSettings, errors, optimise_noise
from kinema.human.sampling import SampleSettings, sample_features
from kinema.human.segments import SegmentPlan, stack_targets
from kinema.human.targets import UserTargets
from kinema.motion.core import Motion
from kinema.objectives.io import ObjectiveError, bind_objectives, load_objectives
from kinema.objectives.snap import snap_constraints
from kinema.objectives.terms import Bound

if TYPE_CHECKING:
    from kinema.human.pipeline import HumanPipeline, SamplingCall


def collect_objectives(constraints, objectives, skeleton, fps: float, num_frames: int) -> list[Bound]:
    """Bound objectives of a call: the constraints file's (a path or a parsed object) then ``objectives``."""
    from_file = []
    source = None
    if isinstance(constraints, str | os.PathLike | dict):
        from_file = load_objectives(constraints)
        source = str(constraints) if isinstance(constraints, str | os.PathLike) else None
    try:
        return bind_objectives(from_file, skeleton, fps, num_frames) + bind_objectives(
            load_objectives(objectives), skeleton, fps, num_frames
        )
    except ObjectiveError as err:
        raise ObjectiveError(err.reason, field=err.field, index=err.index, kind=err.kind, source=source) from None


def sample_with_objectives(
    model: HumanPipeline,
    plan: SegmentPlan,
    call: SamplingCall,
    settings: SampleSettings,
    bound: list[Bound],
    opt: NoiseOptSettings,
    *,
    progress: bool = False,
) -> tuple[list[Motion], list[SegmentPlan], dict]:
    """``call.samples`` raw motions meeting ``bound``, the plan that post-processes each (the call's plan
    plus its snapped targets) and the optimisation report (see optimise_noise; ``"optimised"`` holds the
    values before snapping, ``"after"`` those of the returned raw motions). The noise comes from
    ``call.generator``; the prompt is the segment's, embedded as ``call.texts`` holds it; ``settings``
    (not ``call``) give guidance and DDIM steps (:func:`objective_settings`)."""
    if len(plan.segments) != 1:
        raise KinemaError(
            f"objectives need a single motion of at most {model.max_seconds:g} s; "
            f"this call has {len(plan.segments)} segments"
        )
    heading, samples = call.heading, call.samples
    text = model.prompt_condition(plan.segments[0].prompt, call.texts)
    targets, shift = stack_targets([plan.segment_targets(0, None, heading)] * samples)
    rep, L = model.representation, model.weights_for(plan.segments[0].prompt, call.texts)
    text = None if text is None else text.expand(samples, -1)
    feats, z, report = optimise_noise(L, text, targets, settings, bound, opt, generator=call.generator,
                                      progress=progress)
    plans, counts = [plan] * samples, [0] * samples
    if opt.snap:
        for b in range(samples):
            P = rep.pose(feats[b])
            snapped = snap_constraints(bound, P, rep.skeleton, feats[b][:, rep.root_xz])
            if not snapped:
                continue
            counts[b] = sum(len(c.frames(rep.fps, plan.total_frames)) for c in snapped)
            tg, _ = stack_targets([_with_constraints(plan, rep, snapped).segment_targets(0, None, heading)])
            feats[b] = sample_features(
                L,
                None if text is None else text[b : b + 1],
                tg,
                settings,
                init_noise=z[b : b + 1],
            )[0]
            # post-processing gets the targets snapped again on the resampled motion (it keeps the timing
            # that motion took), time-agnostic paths left out (kinema.objectives.snap)
            again = snap_constraints(bound, rep.pose(feats[b]), rep.skeleton, feats[b][:, rep.root_xz], paths=False)
            plans[b] = _with_constraints(plan, rep, again)
        after = errors(bound, rep.pose(feats))
        report["objectives"] = [
            dict(o, optimised=o["after"], after=a) for o, a in zip(report["objectives"], after, strict=True)
        ]
        report["snapped"] = counts  # targets (constraint frames) imposed when sampling again
    rep.shift_root_xz(feats, shift[:, None])
    return [rep.to_motion(f) for f in feats], plans, report


def _with_constraints(plan: SegmentPlan, rep, extra: list) -> SegmentPlan:
    """``plan`` with ``extra`` constraint objects encoded into its targets and added to its post-processing."""
    T = plan.total_frames
    for c in extra:
        c.check(rep.skeleton, rep.fps, T)
    enc = rep.encode(extra, T)
    u = plan.targets
    on = enc.mask > 0
    x = torch.where(on, enc.x_tgt.float(), u.x_tgt)
    m = torch.maximum(u.mask, enc.mask.float())
    wxz, wm = u.world_xz, u.world_mask
    if bool(enc.world_mask.any()):
        ew = enc.world_mask > 0
        wxz = torch.where(ew[..., None], enc.world_xz.float(), enc.world_xz.float() if wxz is None else wxz)
        wm = torch.maximum(enc.world_mask.float(), torch.zeros_like(enc.world_mask.float()) if wm is None else wm)
    return replace(plan, targets=UserTargets(x, m, wxz, wm), constraints=[*plan.constraints, *extra])


#: post-processing may move an objective this much (metres) and this factor before the raw motion is kept
WORSE_BY_M, WORSE_FACTOR = 0.02, 1.5


def add_final(
    report: dict, bound: list[Bound], motions: list[Motion], raw: list[Motion]
) -> tuple[list[Motion], dict, list[str]]:
    """(motions, report, warnings): each objective's value on the final motions as ``"final"``, and the
    warnings of `worse_than_raw` for what post-processing still left worse.

    Post-processing knows explicit targets, not objectives: removing foot skate can pull a pelvis that
    glided along a time-agnostic path 70 cm off it. Where it leaves an objective more than
    ``WORSE_BY_M`` and ``WORSE_FACTOR`` times worse than on the raw motion, that sample's raw motion is
    kept instead and a warning names the objective and both values."""
    P = torch.stack([m.positions.float() for m in motions])
    R = torch.stack([m.positions.float() for m in raw])
    final, before = errors(bound, P), errors(bound, R)
    out, warnings = list(motions), []
    for i, (b, f_row, r_row) in enumerate(zip(bound, final, before, strict=True)):
        for s, (f, r) in enumerate(zip(f_row, r_row, strict=True)):
            if b.spec.kind != "realism" and f > r + WORSE_BY_M and f > WORSE_FACTOR * r and out[s] is not raw[s]:
                out[s] = raw[s]
                warnings.append(
                    f"post-processing moved objective {i} ({b.spec.kind}) of sample {s} from {100 * r:.1f} cm "
                    f"to {100 * f:.1f} cm; the raw motion is kept for that sample (not foot-locked)"
                )
    final = errors(bound, torch.stack([m.positions.float() for m in out]))
    objs = [dict(o, final=f) for o, f in zip(report["objectives"], final, strict=True)]
    report = dict(report, objectives=objs)
    return out, report, warnings + worse_than_raw(report)


#: a final (post-processed) objective value worse than the raw one by more than this (metres) is warned of
WORSE_SLACK = 0.01


def worse_than_raw(report: dict) -> list[str]:
    """Warnings, one per objective and sample, where post-processing left the objective further off than
    the raw motion (``report`` from add_final): post-processing must never make an objective worse silently."""
    out = []
    for k, o in enumerate(report.get("objectives", [])):
        for i, (raw, final) in enumerate(zip(o.get("after", []), o.get("final", []), strict=False)):
            if final > raw + WORSE_SLACK:
                out.append(
                    f"objective {k} ({o['type']}), sample {i}: post-processing made it worse, "
                    f"{raw * 100:.1f} cm raw -> {final * 100:.1f} cm final"
                )
    return out


def objective_settings(settings: SampleSettings, steps_given: int | None, default_steps: int) -> SampleSettings:
    """The chain's DDIM steps: the caller's ``steps`` when given, else ``default_steps``."""
    return replace(settings, steps=default_steps if steps_given is None else steps_given)
