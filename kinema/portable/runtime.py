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
    heading_of,
    joint_positions,
    pelvis_offset_targets,
    pose_from_local,
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


@dataclass(frozen=True)
class Keyframe:
    """A whole pose at ``time`` seconds: the root joint's world ``root`` (3,) metres and every joint's local
    rotation ``rotations`` (J, 3) axis-angle radians (parent frame -> joint frame; zeros: the rest pose)."""

    time: float
    root: tuple
    rotations: tuple


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
    def targets(self, T: int, waypoints=(), path=(), keyframes=()) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Unnormalised targets and mask ``(T, D)`` of the constraints, or (None, None) without any: full-body
        keyframes, then each waypoint at its frame, then a dense path (keyframes at increasing frames,
        positions linearly interpolated onto every frame between the first and the last); a later entry
        wins, and a keyframe's joint x/z are made relative to its frame's final root x/z."""
        if not waypoints and not path and not keyframes:
            return None, None
        D, fps = self.m["feature_dim"], self.m["fps"]
        rx, rz = self.m["layout"]["root_xz"]
        tgt, mask = np.zeros((T, D), np.float32), np.zeros((T, D), np.float32)

        def frame_of(w, what: str) -> int:
            if not all(math.isfinite(float(v)) for v in (w.x, w.z, w.time) if v is not None):
                raise KinemaError(f"{what} {w}: x, z and time must be finite numbers")
            f = round(w.time * fps)
            if not 0 <= f < T:
                raise KinemaError(f"{what} time {w.time:g} s is outside the motion (0 to {(T - 1) / fps:g} s)")
            return f

        world = {f: xz for f, xz in (self._keyframe(k, tgt, mask, frame_of) for k in keyframes)}
        for w in (w if isinstance(w, Waypoint) else Waypoint(*w) for w in waypoints):
            f = frame_of(w, "waypoint")
            tgt[f, rx], tgt[f, rz] = w.x, w.z
            mask[f, [rx, rz]] = 1.0
        if path:
            keys = [w if isinstance(w, Waypoint) else Waypoint(*w) for w in path]
            frames = [frame_of(w, "path point") for w in keys]
            if len(keys) < 2 or any(b <= a for a, b in zip(frames, frames[1:], strict=False)):
                raise KinemaError("a path needs at least two points at increasing frames")
            full = np.arange(frames[0], frames[-1] + 1)
            tgt[full, rx] = np.interp(full, frames, [w.x for w in keys])
            tgt[full, rz] = np.interp(full, frames, [w.z for w in keys])
            mask[full[:, None], [rx, rz]] = 1.0
        sl = self.m["layout"]["slices"]
        for f, xz in world.items():  # joint x/z relative to the frame's final root
            jp = np.arange(*sl["joint_pos"]).reshape(-1, 3)
            tgt[f, jp[:, 0]] = xz[:, 0] - tgt[f, rx]
            tgt[f, jp[:, 2]] = xz[:, 1] - tgt[f, rz]
        return tgt, mask

    def _keyframe(self, k, tgt: np.ndarray, mask: np.ndarray, frame_of) -> tuple[int, np.ndarray]:
        """Write one full-body keyframe's channels (root position, heading, joint heights, 6D rotations);
        its frame and world joint x/z ``(J, 2)``."""
        sk, sl = self.m["skeleton"], self.m["layout"]["slices"]
        k = k if isinstance(k, Keyframe) else Keyframe(*k)
        J = len(sk["parents"])
        rot, root = np.asarray(k.rotations, dtype=np.float64), np.asarray(k.root, dtype=np.float64)
        if rot.shape != (J, 3) or root.shape != (3,) or not (np.isfinite(rot).all() and np.isfinite(root).all()):
            raise KinemaError(f"keyframe at {k.time} s: root must be 3 finite numbers and rotations {J} x 3")
        if sk.get("left_hip") is None:
            raise KinemaError("this model's skeleton names no hips, so its keyframes have no heading")
        f = frame_of(Waypoint(0.0, 0.0, float(k.time)), "keyframe")
        G, P = pose_from_local(rot, root, sk)
        row = np.zeros(tgt.shape[1])
        row[slice(*sl["root_pos"])] = P[sk["root"]]
        row[slice(*sl["heading"])] = heading_of(P, sk["left_hip"], sk["right_hip"])
        row[slice(*sl["joint_pos"])] = np.stack([np.zeros(J), P[:, 1], np.zeros(J)], -1).reshape(-1)
        row[slice(*sl["joint_rot"])] = np.concatenate([G[:, :, 0], G[:, :, 1]], -1).reshape(-1)
        on = np.zeros(tgt.shape[1], dtype=bool)
        for group in ("root_pos", "heading", "joint_pos", "joint_rot"):
            on[slice(*sl[group])] = True
        tgt[f, on], mask[f, on] = row[on], 1.0
        return f, P[:, [0, 2]]

    # ------------------------------------------------------------------ the loop
    def generate(self, prompt: str, seconds: float, seed: int = 0, waypoints=(), *, path=(), keyframes=(),
                 noise: np.ndarray | None = None, steps: int | None = None,
                 guidance: tuple[float, float] | None = None) -> dict:
        """One raw motion (docs/onnx_runtime.md): ``positions (T, J, 3)`` metres, Y up, plus its features."""
        m = self.m
        if not isinstance(prompt, str) or not prompt.strip():
            raise KinemaError("prompt must be a non-empty text")
        T, D = frames_for(seconds, m["fps"], m["max_frames"]), m["feature_dim"]
        steps = m["schedule"]["steps"] if steps is None else steps
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= m["schedule"]["num_train_steps"]:
            raise KinemaError(f"steps must be an integer in [1, {m['schedule']['num_train_steps']}], got {steps!r}")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise KinemaError(f"seed must be a non-negative integer, got {seed!r}")
        if noise is None:
            noise = standard_normal(seed, (T, D))
        elif noise.shape != (T, D):
            raise KinemaError(f"noise must have shape {(T, D)}, got {noise.shape}")
        text, grounded = self.condition(prompt)
        graph = self.weights_for(prompt, grounded)
        tgt, mask = self.targets(T, waypoints, path, keyframes)
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
