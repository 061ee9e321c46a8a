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
from dataclasses import dataclass, field
from pathlib import Path

import torch

from kinema.diffusion.guidance import Guidance
from kinema.errors import KinemaError
from kinema.generate.keyjoints import FeaturePoser
from kinema.generate.sampling import JOINT_SIGMA_SECONDS, ROOT_SMOOTHING_SECONDS, sample_features
from kinema.generate.segments import SegmentPlan, plan_segments
from kinema.generate.timeline import Segment, crossfade, parse_timeline, split_long
from kinema.model.loading import LoadedModel, load_denoiser
from kinema.motion.core import Motion
from kinema.motion.features import features_to_motion
from kinema.text import TextEncoder, get_text_encoder

#: seconds of overlap between consecutive timeline segments (constrained, then cross-faded)
OVERLAP_SECONDS = 0.5


@dataclass
class GenerationReport:
    """What the last ``generate`` call did: constraint residuals before/after post-processing, timing."""

    seconds: float = 0.0
    segments: int = 1
    residuals: list[dict] = field(default_factory=list)


class KinemaModel:
    """A trained model ready to generate; build it with :func:`load_model`.

    Sampling-time root corrections (kinema.generate.sampling; not in the paper): ``root_displacement``
    (default True) moves the predicted root trajectory onto root constraints and pins a free first frame
    to the origin (or, with root constraints, shifts it with the first one) after every denoising step;
    ``root_smoothing`` (seconds, default 0.25) filters the predicted root x/z; ``joint_sigma`` (seconds,
    default 0.6) spreads each keyjoint's miss into its position channels
    (kinema.generate.keyjoints). Set them to False / 0 / 0 for the paper's imputation alone.
    """

    def __init__(self, loaded: LoadedModel, text_encoder: TextEncoder):
        self.loaded = loaded
        self.text_encoder = text_encoder
        self.last_report = GenerationReport()
        self.root_displacement = True
        self.root_smoothing = ROOT_SMOOTHING_SECONDS
        self.joint_sigma = JOINT_SIGMA_SECONDS

    @property
    def skeleton(self):
        return self.loaded.skeleton

    @property
    def fps(self) -> float:
        return self.loaded.fps

    @property
    def max_seconds(self) -> float:
        return self.loaded.denoiser.config.max_frames / self.fps

    def __repr__(self) -> str:
        return f"KinemaModel({self.loaded.path}, {self.skeleton.num_joints} joints @ {self.fps:g} fps)"

    # ------------------------------------------------------------------ public
    def generate(
        self,
        prompt_or_timeline,
        seconds: float | None = None,
        constraints=None,
        samples: int = 1,
        steps: int | None = None,
        guidance: tuple[float, float] | Guidance | None = None,
        seed: int = 0,
        postprocess: bool = True,
        heading: float = 0.0,
        progress: bool = False,
    ) -> list[Motion]:
        """Generate ``samples`` motions.

        Args:
            prompt_or_timeline: a prompt ("A person walks forward.", "" for no text), a list of
                ``(prompt, seconds)`` / ``{"prompt", "seconds"}`` segments, or a timeline .json path.
            seconds: duration for a single prompt (default 5 s); ignored for timelines.
            constraints: a constraints .json path, a JSON-style list, or constraint objects (see
                docs/constraints.md); frames refer to the whole output at the model's fps.
            samples: how many different motions (same constraints, different noise).
            steps: DDIM steps (default: the model's saved setting).
            guidance: ``(w_text, w_constr)`` or a Guidance (default: the model's saved setting).
            seed: fixes the result.
            postprocess: foot locking + IK + exact constraint hitting.
            heading: first-frame facing in radians about +Y (0 faces +Z).
        """
        import time

        t0 = time.perf_counter()
        segments = self._segments(prompt_or_timeline, seconds)
        guide = self._guidance(guidance)
        total = sum(max(1, round(s.seconds * self.fps)) for s in segments)
        plan = plan_segments(self, segments, constraints, total)
        g = torch.Generator().manual_seed(int(seed))
        motions = []
        for _ in range(int(samples)):
            motions.append(self._generate_one(plan, guide, steps, g, heading, postprocess, progress))
        self.last_report = GenerationReport(time.perf_counter() - t0, len(segments), plan.reports)
        return motions

    # ------------------------------------------------------------------ internals
    def _segments(self, prompt_or_timeline, seconds) -> list[Segment]:
        if isinstance(prompt_or_timeline, str) and not prompt_or_timeline.lower().endswith(".json"):
            seconds = 5.0 if seconds is None else float(seconds)
            if not (math.isfinite(seconds) and seconds > 0):
                raise KinemaError(f"seconds must be positive, got {seconds}")
            return split_long(prompt_or_timeline, seconds, self.max_seconds - OVERLAP_SECONDS)
        segs = parse_timeline(prompt_or_timeline)
        out = []
        for s in segs:
            out += split_long(s.prompt, s.seconds, self.max_seconds - OVERLAP_SECONDS)
        return out

    def _guidance(self, guidance) -> Guidance:
        if guidance is None:
            return self.loaded.guidance
        if isinstance(guidance, Guidance):
            return guidance
        w_text, w_constr = (float(w) for w in guidance)
        return Guidance(mode="separated", w_text=w_text, w_constr=w_constr)

    def encode_text(self, prompt: str) -> torch.Tensor | None:
        return None if not prompt.strip() else self.text_encoder.encode([prompt]).float()

    def _generate_one(self, plan: SegmentPlan, guide, steps, g, heading, postprocess, progress) -> Motion:
        motion: Motion | None = None
        for k, seg in enumerate(plan.segments):
            x_tgt, mask, world_xz, world_mask, c_dir, shift = plan.segment_targets(k, motion, heading)
            text = self.encode_text(seg.prompt)
            feats = sample_features(
                self.loaded.denoiser, self.loaded.sampler, seg.num_frames, text, c_dir[None], guide,
                x_tgt[None], mask[None], steps=steps, generator=g, progress=progress,
                world_xz=None if world_xz is None else world_xz[None],
                world_mask=None if world_mask is None else world_mask[None],
                root_displacement=self.root_displacement, anchor_start=self.root_displacement,
                root_smoothing=self.root_smoothing, joint_sigma=self.joint_sigma,
                joint_poser=FeaturePoser(self.skeleton) if self.joint_sigma > 0 else None,
            )[0]
            feats[:, 0] += shift[0]
            feats[:, 2] += shift[1]
            part = features_to_motion(feats, self.skeleton, self.fps)
            motion = part if motion is None else crossfade(motion, part, seg.overlap)
        assert motion is not None
        if postprocess:
            motion = plan.postprocess(motion)
        return motion


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
        raise KinemaError(f"{path}: no such model folder")
    return path


def load_model(name_or_path: str | Path = "default", text_cache: Path | None = None) -> KinemaModel:
    """Load a model for generation: ``"default"`` or a path to a run/checkpoint folder."""
    loaded = load_denoiser(resolve_model_path(name_or_path))
    encoder = get_text_encoder(loaded.text_encoder_id, cache_dir=text_cache)
    return KinemaModel(loaded, encoder)
