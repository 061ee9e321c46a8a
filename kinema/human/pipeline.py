"""The human pipeline: ``kinema.load_model("default").generate(request)`` for the flat root/body model.

``run`` turns a prompt (or a multi-prompt timeline) plus optional kinematic constraints into
``Motion`` objects on the model's skeleton: text -> embedding, constraints -> imputed feature targets,
DDIM with separated guidance, features -> rotations -> FK, then optional post-processing (foot locking,
IK, exact constraint hitting). Times are seconds, positions metres, Y up, first frame facing ``heading``
radians (0 = +Z) with its root over the origin, unless root constraints (waypoints, paths, keyframes)
place the motion elsewhere in the world.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import kept_steps
from kinema.errors import KinemaError
from kinema.human.continuation import continuation_window, continued, learned_window
from kinema.human.keyjoint_planning import KeyjointPlanner, plans_by_default, sample_with_keyjoint_plan, shipped_planner
from kinema.human.mirrored_request import mirror_constraints, mirrored_prompts
from kinema.human.noise_optimisation import DEFAULT_DDIM_STEPS, DEFAULT_ITERATIONS, NoiseOptSettings
from kinema.human.objective_sampling import add_final, collect_objectives, objective_settings, sample_with_objectives
from kinema.human.sampling import JOINT_SIGMA_SECONDS, ROOT_SMOOTHING_SECONDS, SampleSettings, sample_features
from kinema.human.segments import JOIN_STRENGTH, SegmentPlan, plan_segments, stack_targets
from kinema.model.actions import reworded
from kinema.model.grounding import Grounded, Grounding, as_grounding, ground
from kinema.model.loading import LoadedModel, load_denoiser
from kinema.model.vocabulary import KnownPrompts, PromptMatch
from kinema.motion.core import Motion
from kinema.pipeline.base import MotionPipeline, RigInfo
from kinema.pipeline.progress import ProgressFn, StepProgress, split_progress
from kinema.pipeline.request import GenerationRequest
from kinema.pipeline.result import GenerationReport, GenerationResult
from kinema.pipeline.timeline import Segment, parse_timeline, splice, split_long
from kinema.postprocess.guard import require_finite
from kinema.representation.flat import FlatRepresentation
from kinema.rig import Rig
from kinema.text import TextEncoder


@dataclass(frozen=True)
class SamplingCall:
    """What every denoiser pass of one ``run`` shares: guidance, DDIM steps, the noise generator (one
    stream for all passes, so a seed fixes the result), the first frame's heading, how many samples, the
    (grounded) prompt embeddings and the keyjoint planner, if any."""

    guide: Guidance
    steps: int
    generator: torch.Generator
    heading: float
    samples: int
    texts: dict[str, Grounded]
    planner: KeyjointPlanner | None = None


class HumanPipeline(MotionPipeline):
    """The human model ready to generate; build it with ``kinema.load_model``.

    One instance may be shared by several threads: ``generate`` keeps everything it computes in the
    call (its result carries its own report) and never changes the model or its sampler.

    Sampling-time root corrections (kinema.human.sampling; not in the paper): ``root_displacement``
    (default True) moves the predicted root trajectory onto root constraints and pins a free first frame
    to the origin (or, with root constraints, shifts it with the first one) after every denoising step;
    ``root_smoothing`` (seconds, default 0.25) filters the predicted root x/z; ``joint_sigma`` (seconds,
    default 0.6) spreads each keyjoint's miss into its position channels
    (kinema.human.keyjoints). Set them to False / 0 / 0 for the paper's imputation alone.
    ``grounding`` (kinema.model.grounding) is what a request without grounding fields uses: the model's
    saved setting (``checkpoint.json`` "grounding", else ``DEFAULT_GROUNDING``).
    """

    pipeline_name = "human"
    precisions = ("fp32", "bf16")

    def __init__(self, loaded: LoadedModel, text_encoder: TextEncoder, known_prompts: KnownPrompts | None = None):
        self.loaded = loaded
        self.text_encoder = text_encoder
        self.known_prompts = known_prompts
        self.root_displacement = True
        self.root_smoothing = ROOT_SMOOTHING_SECONDS
        self.joint_sigma = JOINT_SIGMA_SECONDS
        self.guidance_refresh = 1  # > 1: guidance caching (kinema.diffusion.guidance_cache), off by default
        self.guidance_cached = "constr"
        self.grounding: Grounding = loaded.grounding

    @classmethod
    def load(cls, ckpt: Path, text_encoder_for, precision: str = "fp32") -> HumanPipeline:
        loaded = load_denoiser(ckpt, precision=precision)
        known = KnownPrompts.load(loaded.path)
        if known is not None and known.encoder_id != loaded.text_encoder_id:
            raise KinemaError(f"{ckpt}: its known prompts were embedded with {known.encoder_id!r}, the model uses "
                              f"{loaded.text_encoder_id!r}; rebuild them (kinema export --known-prompts DATA)")
        return cls(loaded, text_encoder_for(loaded.text_encoder_id), known)

    @property
    def skeleton(self):
        return self.loaded.skeleton

    @property
    def precision(self) -> str:
        """``"fp32"`` or ``"bf16"``: the dtype of the denoiser's weights (kinema.model.precision)."""
        return self.loaded.precision

    @property
    def representation(self) -> FlatRepresentation:
        """The model's feature representation (rig, layout, statistics) that planning, sampling and
        post-processing work on."""
        return self.loaded.representation

    @property
    def max_seconds(self) -> float:
        return self.loaded.denoiser.config.max_frames / self.fps

    @property
    def window_seconds(self) -> float:
        return self.max_seconds

    def window_for(self, prompt: str) -> float | None:
        return learned_window(self, prompt)

    def rigs(self) -> list[RigInfo]:
        skel = self.skeleton
        return [RigInfo(skel.name or "unnamed", list(skel.names), [int(p) for p in skel.parents], [])]

    def resolve_rig(self, rig) -> Rig:
        """The model's own rig; a request naming another is refused (retargeting is kinema.retarget's)."""
        own = self.rigs()[0].name
        if rig is None or rig == own or rig is self.skeleton:
            return self.representation.rig
        raise KinemaError(f"rig: the model {self.path.name!r} drives its own skeleton {own!r}; use a model "
                          "for any rig (--model creatures) for this rig")

    def __repr__(self) -> str:
        return (f"HumanPipeline({self.loaded.path}, {self.skeleton.num_joints} joints @ {self.fps:g} fps, "
                f"{self.precision})")

    # ------------------------------------------------------------------ public
    def run(self, request: GenerationRequest, *, progress: bool | ProgressFn = False) -> GenerationResult:
        """Generate ``request.samples`` motions; returns them with this call's report (``result.report``).

        Frames of constraints refer to the whole output at the model's fps unless the file states its own
        ``fps`` or ``request.constraints_fps`` is given. Samples share one batch (faster per motion) and
        are post-processed one by one; all draw their noise from one generator stream, so sample i also
        depends on ``samples``. Objectives (docs/objectives.md) are optimised through the noise; a keyjoint
        model (kinema.human.keyjoint_planning) plans pelvis, head, hands and ankles first (one segment, no
        objectives); grounding blends each prompt's embedding with its nearest training captions'
        (kinema.model.grounding); training captions, unknown prompts and prompts without a near caption
        naming the same sides are never grounded.
        """
        self.resolve_rig(request.rig)
        _, steps, _ = self._check_counts(request.samples, request.steps, request.seed)
        if request.timeline is None:  # a prompt longer than its action was captured at: window by window
            seconds = self.default_seconds if request.seconds is None else float(request.seconds)
            window = continuation_window(self, request, seconds)
            if window is not None:
                return continued(self, request, seconds, window, steps)
        return self._sample(request, progress)

    def _sample(self, request: GenerationRequest, progress: bool | ProgressFn) -> GenerationResult:
        """The request made in one go: every segment sampled, the joins regenerated, post-processed."""
        t0 = time.perf_counter()
        r = request
        samples, steps, seed = self._check_counts(r.samples, r.steps, r.seed)
        steps_given = r.steps
        segments = self._segments(r)
        matches = self.match_prompts([s.prompt for s in segments], r.grounding_settings())
        guide = self._guidance(r.guidance)
        plan = plan_segments(self.representation, segments, r.constraints, r.constraints_fps)
        g = torch.Generator().manual_seed(seed)
        bound = collect_objectives(r.constraints, r.objectives, self.skeleton, self.fps, plan.total_frames)
        made_as, sampled = self._mirrored(segments, plan, bool(bound), r.grounding_settings())
        texts = self.ground_prompts([s.prompt for s in sampled.segments], r.grounding_settings())
        planner = self._planner(r.keyjoint_model, sampled, bound)
        obj_report: dict = {}
        call = SamplingCall(guide, steps, g, -r.heading if made_as else r.heading, samples, texts, planner)
        if bound:
            settings = objective_settings(self._settings(plan.segments[0].num_frames, guide, steps), steps_given,
                                          DEFAULT_DDIM_STEPS)
            steps = settings.steps
            opt = NoiseOptSettings(DEFAULT_ITERATIONS if r.objective_steps is None else r.objective_steps)
            raw, plans, obj_report = sample_with_objectives(self, plan, call, settings, bound, opt,
                                                            progress=split_progress(progress)[0])
        else:
            raw = self._sample_batch(sampled, call, progress)
            plans = [plan] * samples  # post-processing hits the user's constraints, in the user's frame
        raw = [m.mirror() for m in raw] if made_as else raw
        t_sampled = time.perf_counter()
        require_finite(raw, "sampling")
        motions, residuals = [], []
        for motion, sample_plan in zip(raw, plans, strict=True):
            motion, report = sample_plan.postprocess(motion) if r.postprocess else (motion, {})
            motions.append(motion)
            residuals.append(report)
        obj_warnings: list[str] = []
        if bound:
            motions, obj_report, obj_warnings = add_final(obj_report, bound, motions, raw)
        warnings = [m.warning() for m in matches if not m.known] + obj_warnings
        warnings += [w for r_ in residuals for w in r_.get("warnings", [])]
        t1 = time.perf_counter()
        report = GenerationReport(
            seconds=t1 - t0, segments=len(segments), frames=plan.total_frames, steps=steps,
            guidance=(guide.w_text, guide.w_constr), guidance_mode=guide.mode.value, seed=seed, residuals=residuals,
            warnings=warnings,
            prompts=[self.prompt_report(m, made_as, texts) for m in matches], objectives=obj_report,
            timings={"sampling": t_sampled - t0, "postprocess": t1 - t_sampled}, joints=self.skeleton.num_joints,
        )
        return GenerationResult(motions, report)

    def prompt_report(self, match: PromptMatch, made_as: dict[str, str], texts: dict[str, Grounded]) -> dict:
        """What the report says of one prompt: how well it is known, how it was grounded, which weights made it
        and, for a request made as its mirror image (kinema.human.mirrored_request), the prompt it was made as."""
        made = made_as.get(match.prompt, match.prompt)
        mirrored = {"made_as_mirror_of": made} if made_as else {}
        weights = self._weights_used(self.conditioned_text(made, texts))
        return match.to_dict() | {"grounding": texts[made].to_dict()} | weights | mirrored

    # ------------------------------------------------------------------ internals
    def conditioned_text(self, prompt: str, texts: dict[str, Grounded] | None) -> str:
        """The words ``prompt`` is conditioned on: the first caption of its grounding blend, else its own.
        The choice of weights (action expert or main) and of mirroring decide on these, as grounding does
        (issue 58: "The man collapses to the ground." is grounded on "Someone collapses and falls forward.",
        which the expert makes and the main weights do not, but its own words name no expert action)."""
        grounded = None if texts is None else texts.get(prompt)
        return grounded.captions[0][0] if grounded is not None and grounded.captions else prompt

    def weights_for(self, prompt: str, texts: dict[str, Grounded] | None) -> LoadedModel:
        """The model that denoises ``prompt``: the action expert's weights or the main ones, by
        :meth:`conditioned_text` (kinema.model.loading.LoadedModel.for_prompt)."""
        return self.loaded.for_prompt(self.conditioned_text(prompt, texts))

    def _mirrored(self, segments: list[Segment], plan: SegmentPlan, objectives: bool,
                  grounding=None) -> tuple[dict[str, str], SegmentPlan]:
        """For a request made as its mirror image (kinema.human.mirrored_request): ``{prompt: the prompt it is
        made as}`` and the plan the sampler runs (mirrored prompts and constraints); else ``({}, plan)``.
        Decided on the words each prompt is conditioned on (:meth:`conditioned_text`)."""
        prompts = [s.prompt for s in segments]
        texts = self.ground_prompts(prompts, grounding)
        made_as = mirrored_prompts(prompts, self.loaded.expert, objectives,
                                   words=lambda p: self.conditioned_text(p, texts))
        cons = mirror_constraints(plan.constraints, self.skeleton) if made_as else None
        if cons is None:
            return {}, plan
        mirrored = [replace(s, prompt=made_as[s.prompt]) for s in segments]
        return made_as, plan_segments(self.representation, mirrored, cons)

    def _weights_used(self, prompt: str) -> dict:
        """For a model with an action expert (kinema.model.action_expert): which weights denoised
        ``prompt``, as ``{"weights": "action expert" | "main"}``; {} for a model without one."""
        if self.loaded.expert is None:
            return {}
        return {"weights": "action expert" if self.loaded.serves_with_expert(prompt) else "main"}

    def _planner(self, keyjoint_model, plan: SegmentPlan, bound) -> KeyjointPlanner | None:
        """The keyjoint planner of a keyjoint-planned call (None for direct), checked against the call.
        Unset (None): the shipped planner when the call's constraints are sparse joint targets alone
        (:func:`kinema.human.keyjoint_planning.plans_by_default`) in one segment without objectives;
        ``"none"``: never."""
        if keyjoint_model == "none":
            return None
        if keyjoint_model is None:
            if bound or len(plan.segments) > 1 or not plans_by_default(plan.constraints, self.skeleton):
                return None
            return self._default_planner()
        if bound:
            raise KinemaError("keyjoint_model (keyjoint planning) cannot be combined with objectives")
        if len(plan.segments) > 1:
            raise KinemaError(f"keyjoint_model (keyjoint planning) plans one segment of up to "
                              f"{self.max_seconds:g} s; this call has {len(plan.segments)} segments")
        if isinstance(keyjoint_model, KeyjointPlanner):
            return keyjoint_model
        if not isinstance(keyjoint_model, str | Path):
            raise KinemaError(f"keyjoint_model: expected 'default', 'none', a keyjoint model folder or a "
                              f"KeyjointPlanner, got {type(keyjoint_model).__name__}")
        if keyjoint_model != "default":
            return KeyjointPlanner.load(keyjoint_model, self.precision)
        planner = self._default_planner()
        if planner is None:
            KeyjointPlanner.check("default")  # not shipped: says so
            raise KinemaError(f"keyjoint_model 'default': the shipped keyjoint model was trained for the default "
                              f"model's text encoder and frame rate, not this model's ({self.text_encoder_id}, "
                              f"{self.fps:g} fps)")
        return planner

    def _default_planner(self) -> KeyjointPlanner | None:
        """The shipped keyjoint planner at the model's precision, loaded once; None when it is not shipped
        or was not trained for this model (another text encoder or frame rate: a model of your own)."""
        if not hasattr(self, "_shipped_planner"):
            planner = KeyjointPlanner.load("default", self.precision) if shipped_planner() else None
            fits = planner is not None and (
                planner.model.config.text_dim == self.loaded.denoiser.config.text_dim
                and planner.info.get("text_encoder") == self.text_encoder_id
                and float(planner.info.get("fps", self.fps)) == float(self.fps)
            )
            self._shipped_planner = planner if fits else None
        return self._shipped_planner

    def _check_counts(self, samples, steps, seed) -> tuple[int, int, int]:
        """Validated ``samples``, ``steps`` (the saved default filled in) and ``seed``."""
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
            raise KinemaError(f"samples must be a positive integer, got {samples!r}")
        if steps is None:
            steps = self.loaded.sampler.num_inference_steps
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= self.max_steps:
            raise KinemaError(f"steps must be an integer in [1, {self.max_steps}] (the model's trained "
                              f"diffusion length), got {steps!r}")
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**64:
            raise KinemaError(f"seed must be an integer in [0, 2**64), got {seed!r}")
        return samples, steps, seed

    def _segments(self, request: GenerationRequest) -> list[Segment]:
        if request.timeline is None:
            seconds = self.default_seconds if request.seconds is None else float(request.seconds)
            return split_long(request.prompt, seconds, self.max_seconds)
        out = []
        for s in parse_timeline(request.timeline):  # each segment in pieces no longer than its action lasts
            window = learned_window(self, s.prompt, request.grounding_settings())
            out += split_long(s.prompt, s.seconds, self.max_seconds if window is None else window)
        return out

    def _guidance(self, guidance) -> Guidance:
        """The call's guidance: the model's own (its saved mode and weights) when the request gives none, else
        separated guidance with the request's two weights (the request checked them)."""
        return Guidance.given(guidance, self.loaded.guidance, mode="separated")

    def encode_text(self, prompt: str) -> torch.Tensor | None:
        return None if not prompt.strip() else self.text_encoder.encode([prompt]).float()

    def grounding_settings(self, grounding=None) -> Grounding:
        """``generate``'s ``grounding`` argument as settings (None: :attr:`grounding`)."""
        return as_grounding(grounding, self.grounding)

    def ground_prompts(self, prompts: list[str], grounding=None) -> dict[str, Grounded]:
        """Per distinct non-empty prompt, the embedding to condition on (kinema.model.grounding)."""
        settings = self.grounding_settings(grounding)
        return {p: ground(p, self.encode_text(p), self.known_prompts, settings, self.encode_reworded(p))
                for p in dict.fromkeys(prompts) if p.strip()}

    def encode_reworded(self, prompt: str) -> torch.Tensor | None:
        """The embedding of ``prompt`` with its action synonyms in the captions' words
        (kinema.model.actions.reworded), or None when that changes nothing: what grounding and the
        unknown-prompt warning fall back on for a prompt too far from the captions in its own words."""
        text = reworded(prompt)
        return None if text == prompt else self.encode_text(text)

    def prompt_condition(self, prompt: str, texts: dict[str, Grounded] | None) -> torch.Tensor | None:
        """The conditioning embedding ``(1, E)`` of a prompt (None for no text), grounded by the model's
        default unless ``texts`` (from :meth:`ground_prompts`) holds it."""
        if not prompt.strip():
            return None
        if texts is None or prompt not in texts:
            texts = self.ground_prompts([prompt])
        return texts[prompt].embedding

    def match_prompts(self, prompts: list[str], grounding=None) -> list[PromptMatch]:
        """Nearest training captions of each distinct non-empty prompt ([] without known prompts), each judged
        also by what the model makes of the caption it is conditioned on (grounded with ``grounding``)."""
        if self.known_prompts is None:
            return []
        distinct = list(dict.fromkeys(p for p in prompts if p.strip()))
        texts = self.ground_prompts(distinct, grounding)
        return [self.known_prompts.match(p, self.encode_text(p)[0], self.encode_reworded(p),
                                         self.conditioned_text(p, texts)) for p in distinct]

    def _settings(self, num_frames: int, guide, steps) -> SampleSettings:
        return SampleSettings(num_frames, guide, steps, root_displacement=self.root_displacement,
                              anchor_start=self.root_displacement, root_smoothing=self.root_smoothing,
                              joint_sigma=self.joint_sigma, guidance_refresh=self.guidance_refresh,
                              guidance_cached=self.guidance_cached)

    def _sample_batch(self, plan: SegmentPlan, call: SamplingCall, progress) -> list[Motion]:
        """``call.samples`` raw motions: every segment sampled on its own (grounded) prompt alone, then every
        join's window regenerated between the two (kinema.human.segments), one batch of all samples per pass.

        Sampling all motions in one denoiser batch is faster per motion than one after another (the
        network runs on larger matrices). Segment k of every sample starts where that sample's motion
        so far ends. Noise: one ``(samples, T, D)`` draw per pass from the call's generator, so a seed fixes
        the result, but sample i is not what a call with fewer samples returned for the same seed.
        """
        motions: list[Motion] = []
        bar, callback = split_progress(progress)
        passes = [call.steps] * len(plan.segments) + [kept_steps(call.steps, JOIN_STRENGTH)] * len(plan.joins)
        counter = None if callback is None else StepProgress(callback, steps=passes)
        for k, seg in enumerate(plan.segments):
            rows = [plan.segment_targets(k, m if k else None, call.heading) for m in motions or [None] * call.samples]
            on_step = None if counter is None else counter.segment(k)
            parts = self._sample_pass(seg.prompt, rows, seg.num_frames, call, bar, on_step)
            motions = parts if k == 0 else [m.concatenate(p) for m, p in zip(motions, parts, strict=True)]
        for j, jn in enumerate(plan.joins):
            rep = self.representation
            rows = [plan.join_targets(j, rep.from_motion(m)) for m in motions]
            on_step = None if counter is None else counter.segment(len(plan.segments) + j)
            windows = self._sample_pass(jn.prompt, rows, jn.num_frames, call, bar, on_step, strength=JOIN_STRENGTH)
            motions = [splice(m, w, jn.lo, jn.fade_in, jn.fade_out) for m, w in zip(motions, windows, strict=True)]
        return motions

    def _sample_pass(self, prompt: str, rows, num_frames: int, call: SamplingCall, bar, on_step,
                     strength: float = 1.0) -> list[Motion]:
        """One denoiser pass over a batch of rows (one per sample) of one prompt; world-placed motions."""
        rep, L = self.representation, self.weights_for(prompt, call.texts)  # the action expert's or the main ones
        targets, shift = stack_targets(rows)
        text = self.prompt_condition(prompt, call.texts)
        text = None if text is None else text.expand(len(rows), -1)
        sample = sample_features if call.planner is None else partial(sample_with_keyjoint_plan, planner=call.planner)
        settings = replace(self._settings(num_frames, call.guide, call.steps), strength=strength)
        feats = sample(L, text, targets, settings, generator=call.generator, progress=bar, on_step=on_step)
        rep.shift_root_xz(feats, shift[:, None])
        return [rep.to_motion(f) for f in feats]

#: the name this class had before the one-pipeline interface (kept for scripts that import it)
KinemaModel = HumanPipeline
