"""Generation with an any-rig model: text + constraints -> motion on any skeleton.

``kinema.load_model("creatures").generate("A fox gallops.", rig="Fox.glb", seconds=4)`` returns an
`AnyRigResult` (a list of `Motion` in metres on the given rig, plus a report). The rig is a GLB/glTF
or BVH file (the skin of a GLB is carried on the skeleton, so saving the motion as .glb keeps the
mesh), a `Skeleton`, a `Rig` (its contact joints and limbs are used), or the id of a training rig
(``model.known_rigs()``).

The rig is scaled to the model's units (rest pose 1 across, as in training), sampled with DDIM in
overlapping windows (kinema.anyrig.sampling), turned to face ``heading``, converted to a
motion (kinema.representation.joint) and finished (kinema.anyrig.finishing): put on the floor, de-jittered,
the exact pass on joint targets, feet locked on the rig's contact joints (any number of legs), scaled back to
metres.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path

import torch

from kinema.anyrig.feet import (
    floor_height,
    floor_root_children,
    rest_extent,
)
from kinema.anyrig.finishing import finish_motion
from kinema.anyrig.heading import heading_from_rate
from kinema.anyrig.rig_file import read_rig_file
from kinema.anyrig.sampling import sample_features, uses_root_stage
from kinema.anyrig.tied import rig_clips, ties_for
from kinema.anyrig.windows import WindowPlan, segment_overlap, segment_plan, single_plan
from kinema.anyrig.world import generate_world, load_constraints_file
from kinema.constraints.character import (
    Constraint,
    JointTarget,
    Keyframe,
    RootMotion,
    RootPath,
)
from kinema.diffusion.guidance import Guidance
from kinema.errors import KinemaError
from kinema.limits import check_rig_joints
from kinema.model.anyrig.loading import LoadedAnyRig, load_anyrig
from kinema.model.skeleton_codes import batch_codes, skeleton_codes
from kinema.pipeline.base import MotionPipeline, RigInfo
from kinema.pipeline.progress import ProgressFn
from kinema.pipeline.request import GenerationRequest
from kinema.pipeline.result import GenerationReport, GenerationResult
from kinema.pipeline.timeline import parse_timeline, segment_bounds
from kinema.representation.joint import ROOT_HEADING_COS, ROOT_HEADING_SIN, JointRepresentation
from kinema.rig import Rig
from kinema.skeleton import Skeleton


class AnyRigPipeline(MotionPipeline):
    """A trained any-rig model ready to generate; build it with ``kinema.load_model``."""

    pipeline_name = "anyrig"
    default_seconds = 4.0
    needs_rig = True

    def __init__(self, loaded: LoadedAnyRig, text_encoder) -> None:
        self.loaded = loaded
        self.text_encoder = text_encoder

    @classmethod
    def load(cls, ckpt: Path, text_encoder_for) -> AnyRigPipeline:
        loaded = load_anyrig(ckpt)
        return cls(loaded, text_encoder_for(loaded.text_encoder_id))

    @property
    def window_seconds(self) -> float:
        return self.loaded.config.window / self.fps

    def __repr__(self) -> str:
        return f"AnyRigPipeline({self.loaded.path}, {len(self.loaded.train_rigs)} training rigs)"

    def known_rigs(self) -> list[tuple[str, int, list[str]]]:
        """(rig id, joints, source files) of every training rig."""
        return [(r.name, len(r.joints), r.files) for r in self.rigs()]

    def rigs(self) -> list[RigInfo]:
        files = self.loaded.rig_files
        out = []
        for rid, d in sorted(self.loaded.train_rigs.items()):
            skel = d["skeleton"]
            out.append(RigInfo(rid, list(skel["names"]), [int(p) for p in skel["parents"]], list(files.get(rid, []))))
        return out

    # ------------------------------------------------------------------ rigs
    def resolve_rig(self, rig: str | Path | Skeleton | Rig) -> Rig:
        """The rig in metres (see the module docstring for what ``rig`` may be)."""
        if isinstance(rig, Rig):
            return rig
        if isinstance(rig, Skeleton):
            return Rig.from_skeleton(rig)
        if rig is None or not isinstance(rig, str | Path):
            ids = ", ".join(r.name for r in self.rigs()) or "none"
            raise KinemaError(f"rig: the any-rig model {self.path.name!r} needs a rig: a GLB/glTF, FBX or BVH file "
                              f"or a training rig id ({ids})")
        path = Path(rig)
        if path.is_file():
            return Rig.from_skeleton(read_rig_file(path, self.fps).skeleton)
        known = self.loaded.train_rigs
        if str(rig) in known:
            return Rig.from_dict(known[str(rig)])
        ids = ", ".join(sorted(known)) or "none"
        raise KinemaError(f"rig {str(rig)!r}: no such file and not a training rig id (known: {ids})")

    # ------------------------------------------------------------------ generation
    def run(self, request: GenerationRequest, *, progress: bool | ProgressFn = False) -> GenerationResult:
        """The request on its rig: character-frame constraint objects or lists (kinema.constraints.character,
        character frame) are sampled directly; docs/constraints.md constraints (world frame) go through
        kinema.anyrig.world, whose notes of what the model cannot take open the warnings."""
        r = request
        _refuse_unsupported(r, self.path.name)
        rig = self.resolve_rig(r.rig)
        fn = progress if callable(progress) else None
        own, world = self._constraints(r, rig, self._what(r), self._seconds(r))
        if not world:
            return self.sample_on_rig(r, rig=rig, constraints=own, progress=fn)
        res, notes, _ = generate_world(self, r, rig=rig, constraints=world, extra=own, progress=fn)
        res.report.left_out = notes
        return res

    def _what(self, r: GenerationRequest):
        """The request's prompt, or its timeline when it has one."""
        return r.prompt if r.timeline is None else r.timeline

    def _seconds(self, r: GenerationRequest) -> float:
        return self.default_seconds if r.seconds is None else r.seconds

    def _constraints(self, r: GenerationRequest, rig: Rig, what, seconds: float) -> tuple[list, list[dict]]:
        """(any-rig constraint objects, world-frame JSON constraints) of a request. A list may mix both
        (a live stream's window: its context as keyframes and root motion, its steering and targets
        as docs/constraints.md JSON)."""
        c = r.constraints
        if c is None:
            return [], []
        own = [o for o in c if isinstance(o, Constraint)] if isinstance(c, list | tuple) else []
        if own and len(own) == len(c):
            return own, []
        rest = [o for o in c if not isinstance(o, Constraint)] if own else c
        more, world = load_constraints_file(rest, rig.skeleton, self.fps, self.frames(what, seconds),
                                            source_fps=r.constraints_fps)
        return own + more, world

    def sample_on_rig(
        self,
        request: GenerationRequest,
        *,
        rig: str | Path | Skeleton | Rig,
        constraints: Sequence[Constraint] = (),
        progress: ProgressFn | None = None,
    ) -> GenerationResult:
        """``request.samples`` motions on ``rig`` for the request's prompt or timeline and ``constraints``
        (kinema.constraints.character, frames at the model's fps, counted over the whole motion; the
        request's own ``constraints`` and ``rig`` are not read here: `run` converts them).

        A prompt ("" = no text) is held for ``request.seconds`` (default `default_seconds`); a timeline
        (kinema.pipeline.timeline) has its segments denoised together by windows that re-play the end of the
        previous segment and are cross-faded with it (kinema.anyrig.windows). ``request.heading`` (radians,
        +Z towards +X): the facing at frame 0 unless a root path or keyframe fixes it. Also read: steps,
        seed, guidance, postprocess. ``progress(done, total)``: after every step."""
        r = request
        samples, seed, heading, postprocess = r.samples, r.seed, r.heading, r.postprocess
        t0 = time.perf_counter()
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
            raise KinemaError(f"samples must be a positive integer, got {samples!r}")
        steps = self._steps(r.steps)
        prompts, plan = self._plan(self._what(r), self._seconds(r))
        T = plan.frames
        rig_m = self.resolve_rig(rig)
        check_rig_joints(rig_m.num_joints, f"rig {rig}" if isinstance(rig, str | Path) else "rig")
        rep_n, scale = self._normalised(rig_m)
        rig_n = rep_n.rig
        constraints = list(constraints)
        targets = rep_n.encode(constraints, scale, T) if constraints else None
        guide = self._guidance(r.guidance)
        codes = batch_codes([skeleton_codes(rig_n, self.loaded.config)], max_hops=self.loaded.config.max_hops)
        stage = self.loaded.root_stage if uses_root_stage(targets, codes) else None
        feats = sample_features(
            self.loaded.denoiser,
            codes,
            r.replace(steps=steps),
            plan=plan,
            text_emb=self._texts(prompts),
            targets=targets,
            sampler=self.loaded.sampler,
            guidance=guide,
            root_stage=stage,
            progress=progress,
        )
        feats = self._orient(feats, rig_n.root, heading, constraints, one_prompt=len(prompts) == 1)
        report = GenerationReport(steps=steps, windows=len(plan.starts), joints=rig_m.num_joints,
                                  segments=len(prompts), frames=T, seed=seed, root_stage=stage is not None)
        t_sampled = time.perf_counter()
        _require_finite(feats)
        ties = self.rig_ties(rig, rig_m).scaled(scale)
        motions = [finish_motion(f, rep_n, rig_m, scale, constraints, postprocess, report, ties) for f in feats]
        report.seconds = time.perf_counter() - t0
        report.timings = {"sampling": t_sampled - t0, "postprocess": report.seconds - (t_sampled - t0)}
        report.guidance, report.guidance_mode = (guide.w_text, guide.w_constr), guide.mode.value
        return GenerationResult(motions, report)

    def _orient(self, feats: torch.Tensor, root: int, heading: float, constraints, *, one_prompt: bool) -> torch.Tensor:
        """Sampled features facing ``heading`` at frame 0, unless a root path or keyframe fixes the facing; a
        single prompt's heading is first read from the model's heading rate (kinema.anyrig.heading; not across
        the joins of a timeline)."""
        if any(isinstance(c, (RootPath, Keyframe, RootMotion)) for c in constraints):
            return feats
        return _face(heading_from_rate(feats, root, self.fps) if one_prompt else feats, root, heading)

    def rig_ties(self, rig, rig_m: Rig):
        """The joint ties of ``rig`` in its units (kinema.anyrig.tied): from its own clips when it is an
        animated GLB/glTF, FBX or BVH file, stored in the checkpoint for a training rig id, else its rest pose."""
        known = str(rig) in self.loaded.train_rigs and isinstance(rig, str | Path) and not Path(rig).is_file()
        stored = self.loaded.info.get("rig_ties", {}).get(str(rig)) if known else None
        return ties_for(rig_m, rig_clips(rig, self.fps), stored)

    def _normalised(self, rig_m: Rig) -> tuple[JointRepresentation, float]:
        """The representation of ``rig_m`` scaled to the model's units (rest pose 1 across) and that scale."""
        scale = 1.0 / rest_extent(rig_m.skeleton)
        rig_n = Rig.from_dict(
            {k: v for k, v in rig_m.to_dict().items() if k != "skeleton"}, skeleton=rig_m.skeleton.scaled(scale)
        )
        return JointRepresentation(rig_n, self.fps), scale

    def frames(self, prompt: str | Sequence | Path, seconds: float = 4.0) -> int:
        """Frames (at ``fps``) that ``generate`` makes for ``prompt`` (a text or a timeline) and ``seconds``."""
        return self._plan(prompt, seconds)[1].frames

    def _steps(self, steps: int | None) -> int:
        n = self.loaded.sampler.num_train_steps
        steps = self.loaded.sampler.num_inference_steps if steps is None else steps
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= n:
            raise KinemaError(f"steps must be an integer in 1..{n}, got {steps!r}")
        return steps

    def _plan(self, prompt, seconds: float) -> tuple[list[str], WindowPlan]:
        """The prompts and the window plan of a single prompt or a timeline (see `generate`)."""
        W = self.loaded.config.window
        if isinstance(prompt, str) and not prompt.lower().endswith(".json"):
            if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
                raise KinemaError(f"seconds must be a positive number, got {seconds!r}")
            return [prompt], single_plan(max(2, round(seconds * self.fps)), W)
        segments = parse_timeline(prompt)
        bounds = segment_bounds(segments, self.fps)
        if bounds[-1] < 2:
            raise KinemaError(f"the timeline lasts {bounds[-1]} frame(s); at least 2 are needed")
        return [s.prompt for s in segments], segment_plan(bounds, W, segment_overlap(self.fps, W))

    def _texts(self, prompts: list[str]) -> torch.Tensor | None:
        """``(P, D)`` embeddings of ``prompts`` (zero rows for empty ones); None when all are empty."""
        real = sorted({p for p in prompts if p})
        if not real:
            return None
        emb = dict(zip(real, self.text_encoder.encode(real), strict=True))
        out = torch.zeros(len(prompts), self.loaded.config.text_dim)
        for i, p in enumerate(prompts):
            if p:
                out[i] = emb[p]
        return out

    def _guidance(self, guidance) -> Guidance:
        """The call's guidance (two weights keep the checkpoint's guidance mode)."""
        return Guidance.given(guidance, self.loaded.guidance)

def _require_finite(feats: torch.Tensor) -> None:
    """A one-line error instead of a NaN motion that fails later without a cause (issue 36)."""
    if not bool(torch.isfinite(feats).all()):
        raise KinemaError("sampling produced NaN or infinite values: an input far outside what the model can take "
                          "(a huge target, heading or weight?)")


def _face(feats: torch.Tensor, root: int, heading: float) -> torch.Tensor:
    """Turn every sample so that its heading at frame 0 is ``heading`` (features are heading-invariant
    except the root's cos/sin of the heading)."""
    out = feats.clone()
    psi = torch.atan2(out[:, :, root, ROOT_HEADING_SIN], out[:, :, root, ROOT_HEADING_COS])
    psi = psi - psi[:, :1] + heading
    out[:, :, root, ROOT_HEADING_COS], out[:, :, root, ROOT_HEADING_SIN] = torch.cos(psi), torch.sin(psi)
    return out


def _refuse_unsupported(r: GenerationRequest, name: str) -> None:
    """One-line errors for the request fields the any-rig model cannot honour."""
    if r.grounding_settings() is not None:
        raise KinemaError(f"grounding: the any-rig model {name!r} keeps no training captions to ground prompts on")
    if r.keyjoint_model is not None:
        raise KinemaError(f"keyjoint_model: keyjoint planning is for the human model; {name!r} is an any-rig model")
    if r.objectives is not None or r.objective_steps is not None:
        raise KinemaError(f"objectives: noise-optimised objectives are for the human model; {name!r} is an any-rig "
                          "model")


#: the names these had before the one-pipeline interface (kept for scripts that import them)
AnyRigModel = AnyRigPipeline
AnyRigResult = GenerationResult
AnyRigReport = GenerationReport

__all__ = [
    "AnyRigModel",
    "AnyRigPipeline",
    "AnyRigReport",
    "AnyRigResult",
    "JointTarget",
    "Keyframe",
    "RootMotion",
    "RootPath",
    "floor_height",
    "floor_root_children",
    "rest_extent",
]
