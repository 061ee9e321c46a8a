"""An exported folder (``kinema export-onnx``) run with onnxruntime and numpy: the reference runtime.

``OnnxHumanModel(folder).generate(prompt, seconds, seed, waypoints)`` follows docs/onnx_runtime.md step
by step and returns ``{"fps", "names", "parents", "positions" (T, J, 3), ...}``; it is the check that the
folder and the written loop are enough to make the motion Python's ``generate(postprocess=False)`` makes.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinema.errors import KinemaError
from kinema.portable.grounding import GroundingTable
from kinema.portable.manifest import FILE_NAME, FORMAT
from kinema.portable.noise import standard_normal
from kinema.portable.sampler import (
    ddim_step,
    displace_root,
    joint_positions,
    pelvis_offset_targets,
    smooth_time,
    spaced_timesteps,
)


@dataclass(frozen=True)
class Waypoint:
    """The smoothed root (the pelvis's ground path) at ``(x, z)`` metres at ``time`` seconds."""

    x: float
    z: float
    time: float


def read_manifest(folder: Path) -> dict:
    path = Path(folder) / FILE_NAME
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise KinemaError(f"{path}: not an exported kinema folder ({err})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise KinemaError(f"{path}: not a {FORMAT} runtime file")
    return manifest


def frames_for(seconds, fps: float, max_frames: int) -> int:
    """``round(seconds * fps)`` (half to even), which must lie in [2, max_frames]."""
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds):
        raise KinemaError(f"seconds must be a number, got {seconds!r}")
    T = round(seconds * fps)
    if not 2 <= T <= max_frames:
        raise KinemaError(f"seconds must be in [{2 / fps:g}, {max_frames / fps:g}], got {seconds:g}")
    return T


class OnnxHumanModel:
    """An exported human model folder, loaded for sampling (module docstring)."""

    def __init__(self, folder: str | Path, precision: str = "fp32"):
        import onnxruntime as ort
        from tokenizers import Tokenizer

        self.folder = Path(folder)
        self.m = m = read_manifest(self.folder)
        if precision not in ("fp32", "fp16"):
            raise KinemaError(f"precision must be 'fp32' or 'fp16', got {precision!r}")
        opts = ort.SessionOptions()
        opts.log_severity_level = 3

        def session(entry):
            return ort.InferenceSession(str(self.folder / entry[precision]), opts, providers=["CPUExecutionProvider"])

        self.sessions = {name: session(entry) for name, entry in m["graphs"].items()}
        self.text_session = session(m["text_encoder"])
        self.tokenizer = Tokenizer.from_file(str(self.folder / m["text_encoder"]["tokenizer"]))
        self.tokenizer.no_padding()
        self.tokenizer.enable_truncation(max_length=m["text_encoder"]["max_tokens"])
        self.grounding = None if m["grounding"] is None else GroundingTable(m["grounding"])
        self.mean = np.asarray(m["normalization"]["mean"], dtype=np.float32)
        self.std = np.asarray(m["normalization"]["std"], dtype=np.float32)
        self.abar = np.asarray(m["schedule"]["alphas_cumprod"], dtype=np.float64)

    # ------------------------------------------------------------------ text
    def embed(self, text: str) -> np.ndarray:
        """The unit MiniLM embedding ``(E,)`` of a text."""
        lower = self.m["text_encoder"]["lower_case"]
        ids = self.tokenizer.encode(text.lower() if lower else text).ids
        feed = {"input_ids": np.array([ids], dtype=np.int64), "attention_mask": np.ones((1, len(ids)), dtype=np.int64)}
        return self.text_session.run(None, feed)[0][0]

    def condition(self, prompt: str) -> tuple[np.ndarray, dict]:
        """The embedding the denoiser is conditioned on and what grounding did."""
        e = self.embed(prompt)
        if self.grounding is None:
            return e, {"status": "off", "captions": []}
        words = self.grounding.reworded(prompt)
        rw = None if words == prompt else self.embed(words)
        emb, status, captions = self.grounding.ground(prompt, e, rw)
        return emb, {"status": status, "captions": captions}

    def weights_for(self, prompt: str, grounded: dict) -> str:
        """The graph that denoises the prompt: the action expert's when the words it is conditioned on (its
        grounding caption, else itself) name one of the expert's actions."""
        expert = self.m.get("action_expert")
        if expert is None or self.grounding is None:
            return "denoiser"
        words = grounded["captions"][0] if grounded["captions"] else prompt
        return "action_expert" if self.grounding.actions(words) & set(expert["actions"]) else "denoiser"

    # ------------------------------------------------------------------ constraints
    def targets(self, T: int, waypoints) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Unnormalised targets and mask ``(T, D)`` of waypoints (root x/z at their frames), or (None, None)."""
        if not waypoints:
            return None, None
        D, fps = self.m["feature_dim"], self.m["fps"]
        rx, rz = self.m["layout"]["root_xz"]
        tgt, mask = np.zeros((T, D), np.float32), np.zeros((T, D), np.float32)
        for w in waypoints:
            w = w if isinstance(w, Waypoint) else Waypoint(*w)
            if not all(math.isfinite(float(v)) for v in (w.x, w.z, w.time)):
                raise KinemaError(f"waypoint {w}: x, z and time must be finite numbers")
            f = round(w.time * fps)
            if not 0 <= f < T:
                raise KinemaError(f"waypoint time {w.time:g} s is outside the motion (0 to {(T - 1) / fps:g} s)")
            tgt[f, rx], tgt[f, rz] = w.x, w.z
            mask[f, [rx, rz]] = 1.0
        return tgt, mask

    # ------------------------------------------------------------------ the loop
    def generate(self, prompt: str, seconds: float, seed: int = 0, waypoints=(), *, noise: np.ndarray | None = None,
                 steps: int | None = None, guidance: tuple[float, float] | None = None) -> dict:
        """One raw motion (docs/onnx_runtime.md): ``positions (T, J, 3)`` metres, Y up, plus its features."""
        m = self.m
        if not isinstance(prompt, str) or not prompt.strip():
            raise KinemaError("prompt must be a non-empty text")
        T, D = frames_for(seconds, m["fps"], m["max_frames"]), m["feature_dim"]
        steps = m["schedule"]["steps"] if steps is None else steps
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= m["schedule"]["num_train_steps"]:
            raise KinemaError(f"steps must be an integer in [1, {m['schedule']['num_train_steps']}], got {steps!r}")
        if noise is None:
            noise = standard_normal(int(seed), (T, D))
        elif noise.shape != (T, D):
            raise KinemaError(f"noise must have shape {(T, D)}, got {noise.shape}")
        text, grounded = self.condition(prompt)
        graph = self.weights_for(prompt, grounded)
        tgt, mask = self.targets(T, waypoints)
        mode, w_text, w_constr = m["guidance"]["mode"], m["guidance"]["w_text"], m["guidance"]["w_constr"]
        if guidance is not None:
            mode, (w_text, w_constr) = "separated", guidance
        if mask is None and mode == "separated":
            mode = "regular"
        branches = {"none": [("text", "constr", 1.0)],
                    "regular": [(None, None, 1 - w_text), ("text", "constr", w_text)],
                    "separated": [(None, None, 1 - w_text - w_constr), ("text", None, w_text),
                                  (None, "constr", w_constr)]}[mode]
        zeros = np.zeros((T, D), np.float32)
        tgt_n = None if mask is None else (tgt - self.mean) / self.std * mask
        feed = {
            "text_emb": np.stack([text if b[0] else np.zeros_like(text) for b in branches]).astype(np.float32),
            "c_dir": np.array([[1.0, 0.0]] * len(branches), dtype=np.float32),
            "x_tgt": np.stack([zeros if tgt_n is None else tgt_n] * len(branches)),
            "mask": np.stack([mask if (b[1] and mask is not None) else zeros for b in branches]),
            "weights": np.array([b[2] for b in branches], dtype=np.float32),
        }
        lay, corr, fps = m["layout"], m["corrections"], m["fps"]
        rxz, pxz = lay["root_xz"], lay["pelvis_xz"]
        origin = (-self.mean[rxz] / self.std[rxz]).astype(np.float32)
        ts = spaced_timesteps(m["schedule"]["num_train_steps"], steps)
        x = noise.astype(np.float32)
        session = self.sessions[graph]
        for i, t in enumerate(ts):
            run = feed | {"x_t": np.stack([x] * len(branches)), "t": np.full(len(branches), t, dtype=np.int64)}
            x0 = session.run(None, run)[0][0]
            x0[:, rxz] = smooth_time(x0[:, rxz], corr["root_smoothing_seconds"] * fps)
            aim = None if mask is None else pelvis_offset_targets(x0, tgt_n, mask, self.mean, self.std, rxz, pxz,
                                                                  corr["root_sigma_seconds"] * fps)
            x0 = displace_root(x0, aim, mask, origin, rxz)
            x = ddim_step(x0, x, self.abar[t], self.abar[ts[i + 1]] if i + 1 < len(ts) else None)
        features = x * self.std + self.mean
        sk = m["skeleton"]
        return {"fps": fps, "names": sk["names"], "parents": sk["parents"],
                "positions": joint_positions(features, lay, sk), "features": features, "grounding": grounded,
                "graph": graph, "guidance": mode}
