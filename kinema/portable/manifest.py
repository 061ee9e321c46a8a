"""``kinema_runtime.json``: everything a runtime without Python needs to sample the human model.

One JSON object (its fields are described in docs/onnx_runtime.md): the graphs and their inputs, the fps
and window, the feature layout, the normalisation statistics, the skeleton, the noise schedule and DDIM
defaults, the guidance, the per-step root corrections, the action expert's routing and the grounding table
(caption texts, their unit embeddings as base64 float16, each caption's words as the grounding rule reads
them, and the regular expressions that read the same from a prompt). Built from the loaded model's own
objects, so the values are the ones Python samples with.
"""

from __future__ import annotations

import base64

import numpy as np

from kinema.diffusion.sampler import spaced_timesteps
from kinema.errors import KinemaError
from kinema.human.sampling import ROOT_SMOOTHING_SECONDS
from kinema.model.actions import ACTION_VERBS, ACTION_WORDS, actions_in
from kinema.model.grounding import _AWAY_FROM_FORWARD, EXACT_ABOVE, off_forward
from kinema.model.loading import LoadedModel
from kinema.model.pace import _JOG, _SLOW, _SPRINT, _STROLL, pace
from kinema.model.sides import _SIDE_WORD, sides
from kinema.model.vocabulary import UNKNOWN_BELOW, KnownPrompts
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS

FORMAT = "kinema-onnx-1"
FILE_NAME = "kinema_runtime.json"
LICENSE = ("The human model's weights (the denoiser graphs) and the grounding table are licensed CC BY-NC 4.0 "
           "(non-commercial use; attribution: kinema, trained on the Bandai Namco Research Motion Dataset). "
           "The text encoder is all-MiniLM-L6-v2 (Apache-2.0).")


def encode_array(values: np.ndarray, dtype: str = "float16") -> dict:
    """A numeric array as ``{"dtype", "shape", "base64"}`` (little-endian)."""
    arr = np.ascontiguousarray(values, dtype=np.dtype(dtype).newbyteorder("<"))
    return {"dtype": dtype, "shape": list(arr.shape), "base64": base64.b64encode(arr.tobytes()).decode("ascii")}


def decode_array(entry: dict) -> np.ndarray:
    """The array of :func:`encode_array`."""
    raw = base64.b64decode(entry["base64"])
    return np.frombuffer(raw, dtype=np.dtype(entry["dtype"]).newbyteorder("<")).reshape(entry["shape"])


def _floats(values) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


def grounding_table(known: KnownPrompts, settings) -> dict:
    """The grounding rule's data (kinema.model.grounding): settings, thresholds, the captions with their
    embeddings and words, and the patterns that read a prompt's words."""
    return {
        "settings": settings.to_dict(),
        "unknown_below": UNKNOWN_BELOW,
        "exact_above": EXACT_ABOVE,
        "captions": list(known.captions),
        "embeddings": encode_array(known.embeddings.numpy(), "float16"),
        "caption_sides": [sorted(sides(c)) for c in known.captions],
        "caption_away": [sorted(off_forward(c)) for c in known.captions],
        "caption_pace": [pace(c) for c in known.captions],
        "caption_manner": [bool(m) for m in known.mannered.tolist()],
        "caption_actions": [sorted(actions_in(c)) for c in known.captions],
        "caption_made": [bool(m) for m in known.made.tolist()],  # False: its action measured not to be made
        "learned_actions": sorted(known.learned),
        "manner_phrases": sorted(known.manner_phrases, key=len, reverse=True),
        "patterns": {  # regular expressions, matched case-insensitively (Python and JavaScript syntax alike)
            "side": _SIDE_WORD.pattern,
            "away": _AWAY_FROM_FORWARD.pattern,
            "actions": {a: r"\b(?:" + "|".join(forms) + r")\b" for a, forms in ACTION_WORDS.items()},
            "action_verbs": dict(ACTION_VERBS),
            "pace": {"sprint": _SPRINT.pattern, "jog": _JOG.pattern, "stroll": _STROLL.pattern, "slow": _SLOW.pattern},
        },
    }


def _hips(skel) -> dict:
    """The hip joints a full-body keyframe's heading is measured between (kinema.motion.heading)."""
    try:
        roles = skel.require_roles(["left_hip", "right_hip"])
    except KinemaError:
        return {"left_hip": None, "right_hip": None}
    return {"left_hip": int(roles["left_hip"]), "right_hip": int(roles["right_hip"])}


def build_manifest(loaded: LoadedModel, known: KnownPrompts | None, graphs: dict, text: dict, source: str) -> dict:
    """The runtime JSON of a loaded human model (module docstring); ``graphs``/``text`` describe the files."""
    rep, sampler, cfg = loaded.representation, loaded.sampler, loaded.denoiser.config
    skel = loaded.skeleton
    layout = loaded.layout.to_dict()
    layout["root_xz"] = list(rep.root_xz)
    layout["pelvis_xz"] = list(rep.pelvis_xz)
    abar = sampler.schedule.alphas_cumprod.double().numpy()
    expert = loaded.expert
    return {
        "format": FORMAT,
        "license": LICENSE,
        "source": source,
        "pipeline": "human",
        "graphs": graphs,
        "text_encoder": text,
        "fps": float(loaded.fps),
        "max_frames": int(cfg.max_frames),
        "feature_dim": int(cfg.feature_dim),
        "text_dim": int(cfg.text_dim),
        "layout": layout,
        "normalization": {"mean": _floats(rep.mean), "std": _floats(rep.std)},
        "skeleton": {"name": skel.name, "names": list(skel.names), "parents": [int(p) for p in skel.parents],
                     "offsets": [_floats(o) for o in skel.offsets], "root": int(rep.rig.root), "up": "+Y",
                     "forward": "+Z", "units": "metres", **_hips(skel)},
        "schedule": {"kind": sampler.schedule.to_dict().get("kind"), "num_train_steps": sampler.num_train_steps,
                     "alphas_cumprod": _floats(abar), "timestep_spacing": sampler.timestep_spacing,
                     "eta": sampler.eta, "steps": sampler.num_inference_steps,
                     "timesteps": spaced_timesteps(sampler.num_train_steps, sampler.num_inference_steps,
                                                   sampler.timestep_spacing)},
        "guidance": loaded.guidance.to_dict(),
        "corrections": {"root_smoothing_seconds": ROOT_SMOOTHING_SECONDS,
                        "root_sigma_seconds": DEFAULT_ROOT_SIGMA_SECONDS, "root_displacement": True,
                        "anchor_start": True},
        "action_expert": None if expert is None else {
            "actions": list(expert.actions), "mirror_side": expert.mirror_side, "graph": "action_expert"},
        "grounding": None if known is None else grounding_table(known, loaded.grounding),
        "noise": {"prng": "mulberry32", "normal": "box-muller", "seed_bits": 32},
    }
