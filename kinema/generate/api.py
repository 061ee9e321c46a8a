"""The public generation API: ``kinema.load_model(...)`` and ``KinemaModel.generate(...)``.

``generate`` turns a prompt (or a multi-prompt timeline) plus optional kinematic constraints into
``Motion`` objects on the model's skeleton: text -> embedding, constraints -> imputed feature targets,
DDIM with separated guidance, features -> rotations -> FK, then optional post-processing (foot locking,
IK, exact constraint hitting). Times are seconds, positions metres, Y up, first frame facing ``heading``
radians (0 = +Z) with its root over the origin, unless root constraints (waypoints, paths, keyframes)
place the motion elsewhere in the world.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import kept_steps
from kinema.errors import KinemaError
from kinema.generate.anyrig_api import AnyRigModel
from kinema.generate.progress import ProgressFn, StepProgress, split_progress
from kinema.generate.results import MotionResults
from kinema.generate.sampling import JOINT_SIGMA_SECONDS, ROOT_SMOOTHING_SECONDS, SampleSettings, sample_features
from kinema.generate.segments import JOIN_STRENGTH, SegmentPlan, plan_segments, stack_targets
from kinema.generate.timeline import Segment, parse_timeline, splice, split_long
from kinema.generate.twostage import KeyjointPlanner, sample_two_stage
from kinema.model.anyrig_loading import is_anyrig_checkpoint, load_anyrig
from kinema.model.grounding import Grounded, Grounding, as_grounding, ground
from kinema.model.loading import LoadedModel, load_denoiser
from kinema.model.vocabulary import KnownPrompts, PromptMatch
from kinema.motion.core import Motion
from kinema.objectives.optimize import DEFAULT_DDIM_STEPS, DEFAULT_ITERATIONS, NoiseOptSettings
from kinema.objectives.sample import add_final, collect_objectives, objective_settings, sample_with_objectives
from kinema.representation.flat import FlatRepresentation
from kinema.text import MemoryCachedEncoder, TextEncoder, get_text_encoder

#: prompt embeddings kept in memory by a loaded model (thread-safe LRU, kinema.text.MemoryCachedEncoder)
TEXT_MEMORY_ENTRIES = 1024


@dataclass
class GenerationReport:
    """What one ``generate`` call did: its settings, timing, constraint residuals and warnings.

    ``residuals`` holds one post-processing report per sample (empty dicts without post-processing):
    ``{"smooth", "foot_lock", "exact": {"before", "after", ...}, "plausibility", "warnings"}``.
    ``warnings`` are the things a user must hear about (a stage undone by the guard, an unreachable
    target, a prompt far from every training caption); the CLI prints them on stderr.
    ``prompts`` holds, per distinct prompt, its nearest training captions and their cosine similarity
    (kinema.model.vocabulary; empty when the model folder has no ``known_prompts.safetensors``) and
    ``grounding``: what prompt grounding did with it (kinema.model.grounding: ``status``, the captions
    blended in with their ``weight`` and the prompt's own ``prompt_weight``).
    """

    seconds: float = 0.0
    segments: int = 1
    frames: int = 0
    steps: int = 0
    guidance: tuple[float, float] = (0.0, 0.0)
    seed: int = 0
    residuals: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    prompts: list[dict] = field(default_factory=list)
    objectives: dict = field(default_factory=dict)


class GenerationResult(MotionResults):
    """The motions of one ``generate`` call (indexable like a list) and that call's own report."""

    report: GenerationReport


class KinemaModel:
    """A trained model ready to generate; build it with :func:`load_model`.

    One instance may be shared by several threads: ``generate`` keeps everything it computes in the
    call (its result carries its own report) and never changes the model or its sampler.

    Sampling-time root corrections (kinema.generate.sampling; not in the paper): ``root_displacement``
    (default True) moves the predicted root trajectory onto root constraints and pins a free first frame
    to the origin (or, with root constraints, shifts it with the first one) after every denoising step;
    ``root_smoothing`` (seconds, default 0.25) filters the predicted root x/z; ``joint_sigma`` (seconds,
    default 0.6) spreads each keyjoint's miss into its position channels
    (kinema.generate.keyjoints). Set them to False / 0 / 0 for the paper's imputation alone.
    ``grounding`` (kinema.model.grounding) is what ``generate(grounding=None)`` uses: the model's saved
    setting (``checkpoint.json`` "grounding", else ``DEFAULT_GROUNDING``).
    """

    def __init__(self, loaded: LoadedModel, text_encoder: TextEncoder, known_prompts: KnownPrompts | None = None):
        self.loaded = loaded
        self.text_encoder = text_encoder
        self.known_prompts = known_prompts
        self.root_displacement = True
        self.root_smoothing = ROOT_SMOOTHING_SECONDS
        self.joint_sigma = JOINT_SIGMA_SECONDS
        self.grounding: Grounding = loaded.grounding

    @property
    def skeleton(self):
        return self.loaded.skeleton

    @property
    def fps(self) -> float:
        return self.loaded.fps

    @property
    def representation(self) -> FlatRepresentation:
        """The model's feature representation (rig, layout, statistics) that planning, sampling and
        post-processing work on."""
        return self.loaded.representation

    @property
    def max_seconds(self) -> float:
        return self.loaded.denoiser.config.max_frames / self.fps

    @property
    def max_steps(self) -> int:
        """The largest number of DDIM steps: the length T of the training noise schedule."""
        return self.loaded.sampler.num_train_steps

    def __repr__(self) -> str:
        return f"KinemaModel({self.loaded.path}, {self.skeleton.num_joints} joints @ {self.fps:g} fps)"

    # ------------------------------------------------------------------ public
    def generate(
        self,
        prompt_or_timeline,
        *,
        seconds: float | None = None,
        constraints=None,
        constraints_fps: float | None = None,
        samples: int = 1,
        steps: int | None = None,
        guidance: tuple[float, float] | Guidance | None = None,
        seed: int = 0,
        postprocess: bool = True,
        heading: float = 0.0,
        progress: bool | ProgressFn = False,
        objectives=None,
        objective_steps: int | None = None,
        keyjoint_model=None,
        grounding: float | Grounding | dict | bool | None = None,
    ) -> GenerationResult:
        """Generate ``samples`` motions; returns them with this call's report (``result.report``).

        Args:
            prompt_or_timeline: a prompt ("A person walks forward.", "" for no text), a list of
                ``(prompt, seconds)`` / ``{"prompt", "seconds"}`` segments, or a timeline .json path.
            seconds: duration for a single prompt (default 5 s); ignored for timelines. The motion has
                exactly ``round(seconds * fps)`` frames.
            constraints: a constraints .json path, a JSON-style list, or constraint objects (see
                docs/constraints.md); frames refer to the whole output at the model's fps unless the
                file states its own ``fps`` or ``constraints_fps`` is given.
            constraints_fps: the frame rate the constraint file's ``frame_indices`` were written at.
            samples: how many different motions (same constraints, different noise), sampled as one
                batch (faster per motion) and post-processed one by one.
            steps: DDIM steps for this call (default: the model's saved setting), 1..``max_steps``.
            guidance: ``(w_text, w_constr)`` >= 0 or a Guidance (default: the model's saved setting).
            seed: fixes the result (0 <= seed < 2**64) for a given ``samples``: all samples draw their
                noise from one generator stream, so sample i also depends on ``samples``.
            postprocess: foot locking + IK + exact constraint hitting, guarded (kinema.postprocess.guard).
            heading: first-frame facing in radians about +Y (0 faces +Z).
            objectives: implicit controls met by optimising the diffusion noise (kinema.objectives,
                docs/objectives.md): JSON-style dicts or Objective objects, added to a constraints file's
                ``"objectives"``; the chain then runs ``steps`` (default 5) DDIM steps.
            objective_steps: Adam iterations on the noise (default 12 when there are objectives).
            keyjoint_model: two-stage control (kinema.generate.twostage, docs/constraints.md): ``"default"``
                (the shipped keyjoint model), a keyjoint model folder or a loaded ``KeyjointPlanner``;
                the keyjoints (pelvis, head, hands, ankles) are planned first from the constraints,
                then the body follows them. One segment (up to ``max_seconds``), no objectives.
            grounding: condition on a blend of each prompt's embedding and its nearest training captions'
                (kinema.model.grounding, docs/evaluation.md): a weight in [0, 1], a ``Grounding``, its dict,
                False (off) or None (:attr:`grounding`, the model's saved default); a weight alone keeps
                the default's temperature and top k. Training captions, unknown prompts (see the
                warnings) and prompts without a near caption naming the same sides are never grounded;
                timeline segments are grounded one by one. ``report.prompts`` says on which captions, with what weights.
            progress: True shows a tqdm bar; a callable ``fn(done, total)`` is called with the denoiser
                steps done so far out of ``steps x segments`` (kinema.generate.progress); it never
                changes the result.
        """
        t0 = time.perf_counter()
        steps_given = steps
        samples, steps, seed = self._check_counts(samples, steps, seed)
        segments = self._segments(prompt_or_timeline, seconds)
        matches = self.match_prompts([s.prompt for s in segments])
        texts = self.ground_prompts([s.prompt for s in segments], grounding)
        guide = self._guidance(guidance)
        plan = plan_segments(self.representation, segments, constraints, constraints_fps)
        g = torch.Generator().manual_seed(seed)
        bound = collect_objectives(constraints, objectives, self.skeleton, self.fps, plan.total_frames)
        planner = self._planner(keyjoint_model, plan, bound)
        obj_report: dict = {}
        if bound:
            settings = objective_settings(self._settings(plan.segments[0].num_frames, guide, steps), steps_given,
                                          DEFAULT_DDIM_STEPS)
            steps = settings.steps
            opt = NoiseOptSettings(DEFAULT_ITERATIONS if objective_steps is None else objective_steps)
            text = self._text(plan.segments[0].prompt, texts)
            raw, plans, obj_report = sample_with_objectives(self, plan, settings, text, g, heading, samples, bound,
                                                            opt, split_progress(progress)[0])
        else:
            raw = self._sample_batch(plan, guide, steps, g, heading, samples, progress, planner, texts)
            plans = [plan] * samples
        motions, residuals = [], []
        for motion, sample_plan in zip(raw, plans, strict=True):
            motion, report = sample_plan.postprocess(motion) if postprocess else (motion, {})
            motions.append(motion)
            residuals.append(report)
        obj_warnings: list[str] = []
        if bound:
            motions, obj_report, obj_warnings = add_final(obj_report, bound, motions, raw)
        warnings = [m.warning() for m in matches if not m.known] + obj_warnings
        warnings += [w for r in residuals for w in r.get("warnings", [])]
        report = GenerationReport(
            seconds=time.perf_counter() - t0, segments=len(segments), frames=plan.total_frames, steps=steps,
            guidance=(guide.w_text, guide.w_constr), seed=seed, residuals=residuals, warnings=warnings,
            prompts=[m.to_dict() | {"grounding": texts[m.prompt].to_dict()} for m in matches], objectives=obj_report,
        )
        return GenerationResult(motions, report)

    # ------------------------------------------------------------------ internals
    def _planner(self, keyjoint_model, plan: SegmentPlan, bound) -> KeyjointPlanner | None:
        """The keyjoint planner of a two-stage call (None for single-stage), checked against the call."""
        if keyjoint_model is None:
            return None
        if bound:
            raise KinemaError("keyjoint_model (two-stage control) cannot be combined with objectives")
        if len(plan.segments) > 1:
            raise KinemaError(f"keyjoint_model (two-stage control) plans one segment of up to "
                              f"{self.max_seconds:g} s; this call has {len(plan.segments)} segments")
        return keyjoint_model if isinstance(keyjoint_model, KeyjointPlanner) else KeyjointPlanner.load(keyjoint_model)

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

    def _segments(self, prompt_or_timeline, seconds) -> list[Segment]:
        if isinstance(prompt_or_timeline, str) and not prompt_or_timeline.lower().endswith(".json"):
            seconds = 5.0 if seconds is None else float(seconds)
            if not (math.isfinite(seconds) and seconds > 0):
                raise KinemaError(f"seconds must be positive, got {seconds}")
            return split_long(prompt_or_timeline, seconds, self.max_seconds)
        segs = parse_timeline(prompt_or_timeline)
        out = []
        for s in segs:
            out += split_long(s.prompt, s.seconds, self.max_seconds)
        return out

    def _guidance(self, guidance) -> Guidance:
        if guidance is None:
            return self.loaded.guidance
        if isinstance(guidance, Guidance):
            return guidance
        try:
            w_text, w_constr = (float(w) for w in guidance)
        except (TypeError, ValueError):
            raise KinemaError(f"guidance must be two numbers (w_text, w_constr), got {guidance!r}") from None
        for name, w in (("w_text", w_text), ("w_constr", w_constr)):
            if not (math.isfinite(w) and w >= 0):
                raise KinemaError(f"guidance {name} must be a finite number >= 0 (0 = no guidance, 1 = the "
                                  f"conditional model alone, > 1 = stronger), got {w}")
        return Guidance(mode="separated", w_text=w_text, w_constr=w_constr)

    def encode_text(self, prompt: str) -> torch.Tensor | None:
        return None if not prompt.strip() else self.text_encoder.encode([prompt]).float()

    def grounding_settings(self, grounding=None) -> Grounding:
        """``generate``'s ``grounding`` argument as settings (None: :attr:`grounding`)."""
        return as_grounding(grounding, self.grounding)

    def ground_prompts(self, prompts: list[str], grounding=None) -> dict[str, Grounded]:
        """Per distinct non-empty prompt, the embedding to condition on (kinema.model.grounding)."""
        settings = self.grounding_settings(grounding)
        return {p: ground(p, self.encode_text(p), self.known_prompts, settings)
                for p in dict.fromkeys(prompts) if p.strip()}

    def _text(self, prompt: str, texts: dict[str, Grounded] | None) -> torch.Tensor | None:
        """The conditioning embedding ``(1, E)`` of a prompt (None for no text), grounded by the model's
        default unless ``texts`` (from :meth:`ground_prompts`) holds it."""
        if not prompt.strip():
            return None
        if texts is None or prompt not in texts:
            texts = self.ground_prompts([prompt])
        return texts[prompt].embedding

    def match_prompts(self, prompts: list[str]) -> list[PromptMatch]:
        """Nearest training captions of each distinct non-empty prompt ([] without known prompts)."""
        if self.known_prompts is None:
            return []
        distinct = dict.fromkeys(p for p in prompts if p.strip())
        return [self.known_prompts.match(p, self.encode_text(p)[0]) for p in distinct]

    def _generate_one(self, plan: SegmentPlan, guide, steps, g, heading, postprocess, progress):
        """One motion (all segments and their regenerated joins) and its post-processing report ({} when off)."""
        motion = self._sample_batch(plan, guide, steps, g, heading, 1, progress)[0]
        return plan.postprocess(motion) if postprocess else (motion, {})

    def _settings(self, num_frames: int, guide, steps) -> SampleSettings:
        return SampleSettings(num_frames, guide, steps, root_displacement=self.root_displacement,
                              anchor_start=self.root_displacement, root_smoothing=self.root_smoothing,
                              joint_sigma=self.joint_sigma)

    def _sample_batch(self, plan: SegmentPlan, guide, steps, g, heading, samples: int, progress,
                      planner: KeyjointPlanner | None = None,
                      texts: dict[str, Grounded] | None = None) -> list[Motion]:
        """``samples`` raw motions: every segment sampled on its own (grounded) prompt alone, then every
        join's window regenerated between the two (kinema.generate.segments), one batch of all samples per pass.

        Sampling all motions in one denoiser batch is faster per motion than one after another (the
        network runs on larger matrices). Segment k of every sample starts where that sample's motion
        so far ends. Noise: one ``(samples, T, D)`` draw per pass from ``g``, so a seed fixes the
        result, but sample i is not what a call with fewer samples returned for the same seed.
        """
        motions: list[Motion] = []
        bar, callback = split_progress(progress)
        passes = [steps] * len(plan.segments) + [kept_steps(steps, JOIN_STRENGTH)] * len(plan.joins)
        counter = None if callback is None else StepProgress(callback, steps=passes)
        run = partial(self._sample_pass, guide=guide, steps=steps, g=g, bar=bar, planner=planner, texts=texts)
        for k, seg in enumerate(plan.segments):
            rows = [plan.segment_targets(k, m if k else None, heading) for m in motions or [None] * samples]
            parts = run(seg.prompt, rows, seg.num_frames, None if counter is None else counter.segment(k))
            motions = parts if k == 0 else [m.concatenate(p) for m, p in zip(motions, parts, strict=True)]
        for j, jn in enumerate(plan.joins):
            rep = self.representation
            rows = [plan.join_targets(j, rep.from_motion(m)) for m in motions]
            on_step = None if counter is None else counter.segment(len(plan.segments) + j)
            windows = run(jn.prompt, rows, jn.num_frames, on_step, strength=JOIN_STRENGTH)
            motions = [splice(m, w, jn.lo, jn.fade_in, jn.fade_out) for m, w in zip(motions, windows, strict=True)]
        return motions

    def _sample_pass(self, prompt: str, rows, num_frames: int, on_step, *, guide, steps, g, bar,
                     planner: KeyjointPlanner | None, texts: dict[str, Grounded] | None = None,
                     strength: float = 1.0) -> list[Motion]:
        """One denoiser pass over a batch of rows (one per sample) of one prompt; world-placed motions."""
        rep, L = self.representation, self.loaded
        targets, shift = stack_targets(rows)
        text = self._text(prompt, texts)
        text = None if text is None else text.expand(len(rows), -1)
        sample = sample_features if planner is None else partial(sample_two_stage, planner=planner)
        settings = replace(self._settings(num_frames, guide, steps), strength=strength)
        feats = sample(L.denoiser, L.sampler, rep, text, targets, settings, generator=g, progress=bar, on_step=on_step)
        rep.shift_root_xz(feats, shift[:, None])
        return [rep.to_motion(f) for f in feats]


def resolve_model_path(name_or_path: str | Path) -> Path:
    """``"default"`` (the model shipped inside the package) or a run / checkpoint folder."""
    if str(name_or_path) in ("default", ""):
        from importlib.resources import files

        shipped = Path(str(files("kinema") / "assets" / "models" / "default"))
        if not (shipped / "checkpoint.json").exists():
            raise KinemaError("this kinema install ships no default model yet; pass a checkpoint with --model PATH")
        return shipped
    path = Path(name_or_path)
    if not path.exists():
        from importlib.resources import files

        shipped = Path(str(files("kinema") / "assets" / "models")) / str(name_or_path)
        if path.name == str(name_or_path) and (shipped / "checkpoint.json").exists():
            return shipped  # another model shipped inside the package, e.g. "creatures"
        raise KinemaError(f"{path}: no such model folder")
    return path


def load_model(name_or_path: str | Path = "default", text_cache: Path | None = None,
               text_memory: int = TEXT_MEMORY_ENTRIES) -> KinemaModel | AnyRigModel:
    """Load a model for generation: ``"default"`` or a path to a run/checkpoint folder.

    Prompt embeddings are kept in memory (the last ``text_memory`` prompts, thread-safe LRU; 0 = off),
    so repeated prompts are encoded once per process; ``text_cache`` (a folder) adds a disk cache
    behind it that persists between processes (the CLI passes ``cache/text``).
    """
    path = resolve_model_path(name_or_path)
    loaded = load_anyrig(path) if is_anyrig_checkpoint(path) else load_denoiser(path)
    encoder = get_text_encoder(loaded.text_encoder_id, cache_dir=text_cache)
    if text_memory:
        encoder = MemoryCachedEncoder(encoder, text_memory)
    if not isinstance(loaded, LoadedModel):
        return AnyRigModel(loaded, encoder)  # a model for any rig (kinema.generate.anyrig_api)
    known = KnownPrompts.load(loaded.path)
    if known is not None and known.encoder_id != loaded.text_encoder_id:
        raise KinemaError(f"{path}: its known prompts were embedded with {known.encoder_id!r}, the model uses "
                          f"{loaded.text_encoder_id!r}; rebuild them (kinema export --known-prompts DATA)")
    return KinemaModel(loaded, encoder, known)
