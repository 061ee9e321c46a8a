"""A small synthetic dataset in the Bandai Namco layout, for tests and for smoke-testing an install.

The real Bandai Namco data (CC BY-NC 4.0, about 3.5 hours) is not shipped with kinema and not present
on every machine, yet the data build, training, evaluation and generation code all read that layout.
`write_synthetic_bandai` writes a few dozen procedurally animated clips in exactly that layout, in well
under a second, so the whole pipeline can run anywhere::

    root/Bandai-Namco-Research-Motiondataset-N/cfg/{content,style}_label.txt   (the real label lists)
    root/Bandai-Namco-Research-Motiondataset-N/data/dataset-N_<content>_<style>_<take>.bvh.gz
    root/Bandai-Namco-Research-Motiondataset-N/data/dataset-N_<content>_<style>_<take>.json

Like the real files, each BVH is 30 fps, in centimetres, Y up, with the same 22-joint hierarchy
(a static ``joint_Root`` whose child ``Hips`` carries the world translation), 6 channels per joint
(``Xposition Yposition Zposition Zrotation Xrotation Yrotation``; the position channels of joints
below the hips repeat their offsets) and zero-length End Sites. Unlike Bandai's rig, whose rest pose
lies along +X, the synthetic rest pose (all rotations zero) stands facing +Z with arms hanging, and
``+X`` is the character's left. Bone lengths are close to Bandai's (pelvis 93 cm up, toes 4 cm).

The motions are simple but physically sensible: in walks and runs the pelvis travels along the heading
(+Z unless the clip turns) while each foot stays exactly planted during its stance and swings forward in
an arc (legs solved by analytic two-bone IK), the arms counter-swing. Feet stay flat (no heel roll), so
the pelvis of a walk bobs more (about 12 cm) than in captured walks (5 cm). Gestures stand still with planted
feet while the named arm(s) rise or wave; ``bow`` flexes the spine; ``dance-short`` marches in place
while turning a full circle. Styles change speed, tempo, amplitude and trunk lean; takes differ by
small seeded variations. Everything is deterministic (same bytes on every run and machine).
"""

from __future__ import annotations

import functools
import gzip
import io
import json
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

FPS = 30.0
#: (name, parent, offset in cm), in the order of the Bandai hierarchy. Y up, +Z forward, +X = left.
JOINTS: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("joint_Root", None, (0.0, 0.0, 0.0)), ("Hips", "joint_Root", (0.0, 93.0, 0.0)),
    ("Spine", "Hips", (0.0, 15.7, 0.0)), ("Chest", "Spine", (0.0, 9.0, 0.0)),
    ("Neck", "Chest", (0.0, 16.4, 0.0)), ("Head", "Neck", (0.0, 6.5, 0.0)),
    *(j for s, x in (("L", 1.0), ("R", -1.0)) for j in (
        (f"Shoulder_{s}", "Chest", (5.0 * x, 13.0, 0.0)),
        (f"UpperArm_{s}", f"Shoulder_{s}", (5.3 * x, 0.0, 0.0)),
        (f"LowerArm_{s}", f"UpperArm_{s}", (0.0, -24.3, 0.0)),
        (f"Hand_{s}", f"LowerArm_{s}", (0.0, -22.3, 0.0)))),
    *(j for s, x in (("L", 1.0), ("R", -1.0)) for j in (
        (f"UpperLeg_{s}", "Hips", (6.5 * x, -2.3, 0.0)),
        (f"LowerLeg_{s}", f"UpperLeg_{s}", (0.0, -39.0, 0.0)),
        (f"Foot_{s}", f"LowerLeg_{s}", (0.0, -40.0, 0.0)),
        (f"Toes_{s}", f"Foot_{s}", (0.0, -7.5, 9.0)))),
)
THIGH, SHIN, ANKLE_HEIGHT, HIP_DROP = 39.0, 40.0, 11.7, 2.3  # cm; the ankle's height when standing
#: The real label files (their order is what the JSON twins index).
LABELS = {
    1: ("walk run dash walk-back walk-left walk-right bow bye guide byebye respond call punch kick slash "
        "dance-long dance-short".split(),
        "normal happy sad angry proud not-confident masculinity feminine childish old tired active musical "
        "giant chimpira".split()),
    2: ("walk walk-turn-left walk-turn-right run wave-both-hands wave-left-hand wave-right-hand "
        "raise-up-both-hands raise-up-left-hand raise-up-right-hand".split(),
        "active elderly exhausted feminine masculine normal youthful".split()),
}
#: What is generated: dataset number -> (contents, styles, takes per content and style).
CLIPS = {
    1: (("walk", "run", "bow", "bye", "dance-short"), ("normal", "happy", "old"), 1),
    2: (("walk", "run", "wave-both-hands", "wave-left-hand", "wave-right-hand", "raise-up-both-hands",
         "raise-up-left-hand", "raise-up-right-hand"), ("normal", "elderly"), 3),
}
DURATION_S = {"walk": 4.0, "run": 3.0, "bow": 3.5, "dance-short": 4.0}  # gestures: 3 s
#: Clips whose length is pinned: tests use frames up to 7.5 s of this walk, as on the real clip, and the
#: six-clip test build (which takes the dance) needs one clip of 5 s or more, as the real one has.
PINNED_DURATION_S = {"dataset-2_walk_normal_001": 9.0, "dataset-1_dance-short_happy_001": 5.5}


@dataclass(frozen=True)
class Style:
    """How a style changes a clip: speed and tempo factors, amplitude factor, extra forward lean (rad)."""

    speed: float = 1.0
    tempo: float = 1.0
    amplitude: float = 1.0
    lean: float = 0.0


STYLES = {"normal": Style(), "happy": Style(1.12, 1.1, 1.4, -0.03), "old": Style(0.7, 0.85, 0.6, 0.2),
          "elderly": Style(0.72, 0.85, 0.6, 0.18)}


@dataclass(frozen=True)
class Gait:
    """Stepping parameters. Lengths in cm, speeds in cm/s, angles in radians.

    ``cadence`` is in gait cycles (two steps) per second; ``stance`` is the fraction of a cycle a foot is
    planted (> 0.5 walks, < 0.5 runs with a flight phase); ``bob`` > 0 puts the pelvis highest at
    mid-stance (walking), < 0 lowest (running). With ``speed`` = ``lift`` = 0 the figure stands still.
    """

    speed: float = 0.0
    turn: float = 0.0  # rad/s, heading change (positive turns towards +X, the left)
    cadence: float = 0.35
    stance: float = 0.6
    lift: float = 0.0
    height: float = 93.0  # mean pelvis height; lowered where needed so the legs reach the feet
    bob: float = 0.0
    sway: float = 0.8
    twist: float = 0.0  # pelvis yaw oscillation
    lean: float = 0.0
    arm_swing: float = 0.0
    elbow: float = 0.2
    reach: float = 0.995  # largest hip-ankle distance as a fraction of the leg length (Bandai walks: 0.97)


GAITS = {
    "walk": Gait(speed=135.0, cadence=0.9, stance=0.55, lift=10.0, height=93.5, sway=1.5,
                 twist=0.07, lean=0.04, arm_swing=0.3, elbow=0.25, reach=0.97),
    "run": Gait(speed=260.0, cadence=1.4, stance=0.3, lift=9.0, height=85.0, bob=-2.0, sway=1.0,
                twist=0.1, lean=0.15, arm_swing=0.5, elbow=1.3, reach=0.97),
    "dance-short": Gait(cadence=1.1, stance=0.6, lift=12.0, height=91.0, bob=1.5, sway=2.5, reach=0.98),
}


# --------------------------------------------------------------------------------------- rotations
def _rot(axis: str, angle) -> np.ndarray:
    """(T, 3, 3) right-handed rotation matrices about ``axis`` ("x", "y" or "z") by ``angle`` (rad)."""
    a = np.atleast_1d(np.asarray(angle, dtype=np.float64))
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    rows = {"x": ((o, z, z), (z, c, -s), (z, s, c)), "y": ((c, z, s), (z, o, z), (-s, z, c)),
            "z": ((c, -s, z), (s, c, z), (z, z, o))}[axis]
    return np.stack([np.stack(r, -1) for r in rows], -2)


def _mul(*mats: np.ndarray) -> np.ndarray:
    """The product of (T, 3, 3) or (1, 3, 3) rotation stacks, left to right."""
    return functools.reduce(np.matmul, mats)


def _euler_zxy_deg(R: np.ndarray) -> np.ndarray:
    """(T, 3) BVH angles (z, x, y) in degrees with ``R = Rz @ Rx @ Ry``, unwrapped over time."""
    x = np.arcsin(np.clip(R[:, 2, 1], -1.0, 1.0))
    y = np.arctan2(-R[:, 2, 0], R[:, 2, 2])
    z = np.arctan2(-R[:, 0, 1], R[:, 1, 1])
    return np.unwrap(np.degrees(np.stack([z, x, y], -1)), period=360.0, axis=0)


def _envelope(t: np.ndarray, up: tuple[float, float], down: tuple[float, float]) -> np.ndarray:
    """0 -> 1 smoothly over the times ``up``, back to 0 over ``down`` (seconds)."""
    u, d = (np.clip((t - a) / (b - a), 0.0, 1.0) for a, b in (up, down))
    return u * u * (3 - 2 * u) * (1.0 - d * d * (3 - 2 * d))


# --------------------------------------------------------------------------------------- gait
def _path(t: np.ndarray, g: Gait, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ground point (T, 2) as (x, z) in cm and heading (T,): off along +Z at ``g.speed``, turning at ``g.turn``."""
    psi = g.turn * t
    if abs(g.turn) < 1e-9:
        return start + g.speed * t[:, None] * np.array([0.0, 1.0]), psi
    return start + g.speed / g.turn * np.stack([1.0 - np.cos(psi), np.sin(psi)], -1), psi


def _feet(t: np.ndarray, g: Gait, phase0: float, path) -> dict:
    """Per side: ankle targets (T, 3) and foot yaw (T,). Planted feet do not move at all.

    Foot j of a side is put down under its hip at the mid-stance time of its j-th cycle; in swing it
    moves to the next footprint along a smooth profile and lifts by ``g.lift`` at mid-swing."""
    out = {}
    for side, sign, shift in (("L", 1.0, 0.0), ("R", -1.0, 0.5)):
        p = g.cadence * t + phase0 + shift
        k = np.floor(p)
        u = p - k  # phase within the current cycle: stance for u < g.stance
        s = np.clip((u - g.stance) / (1.0 - g.stance), 0.0, 1.0)
        prof = 0.5 - 0.5 * np.cos(np.pi * s)

        def footprint(j, sign=sign, shift=shift):
            ground, psi = path((j + g.stance / 2 - phase0 - shift) / g.cadence)
            x = ground[:, 0] + sign * 8.0 * np.cos(psi)
            z = ground[:, 1] - sign * 8.0 * np.sin(psi)
            return np.stack([x, z], -1), psi

        (a, ya), (b, yb) = footprint(k), footprint(k + 1)
        xz = a + prof[:, None] * (b - a)
        y = ANKLE_HEIGHT + g.lift * np.sin(np.pi * s)
        out[side] = (np.stack([xz[:, 0], y, xz[:, 1]], -1), ya + prof * (yb - ya))
    return out


def _pelvis_height(base: np.ndarray, root_xz: np.ndarray, psi: np.ndarray, feet: dict, reach: float) -> np.ndarray:
    """Pelvis height (T,) in cm: ``base``, lowered where needed so that both legs reach their ankle targets.

    A soft minimum (0.5 cm wide) of ``base`` and, per leg, the highest pelvis whose hip is ``reach`` of
    the leg length from the ankle target: smooth, never above any of them. So the stance leg is nearly
    straight and the pelvis vaults over it (highest at mid-stance), as in real walking."""
    limits = [base]
    for s, sign in (("L", 1.0), ("R", -1.0)):
        ankle = feet[s][0]
        hip_x, hip_z = root_xz[:, 0] + sign * 6.5 * np.cos(psi), root_xz[:, 1] - sign * 6.5 * np.sin(psi)
        h2 = (ankle[:, 0] - hip_x) ** 2 + (ankle[:, 2] - hip_z) ** 2
        limits.append(ankle[:, 1] + HIP_DROP + np.sqrt(np.maximum((reach * (THIGH + SHIN)) ** 2 - h2, 0.0)))
    L = np.stack(limits)
    low = L.min(0)
    return low - 0.5 * np.log(np.exp(-(L - low) / 0.5).sum(0))


def _body(t: np.ndarray, g: Gait, rng: np.random.Generator) -> dict:
    """Pelvis, spine, neck and swinging arms of a gait; legs are solved later by `_legs`."""
    start, phase0 = rng.uniform(-50, 50, 2), float(rng.uniform(0, 1))
    path = lambda tt: _path(tt, g, start)  # noqa: E731
    ground, psi = path(t)
    pl = g.cadence * t + phase0
    mid = 2 * np.pi * (pl - g.stance / 2)
    side = g.sway * np.cos(mid)
    xz = np.stack([ground[:, 0] + side * np.cos(psi), ground[:, 1] - side * np.sin(psi)], -1)
    feet = _feet(t, g, phase0, path)
    y = _pelvis_height(g.height + g.bob * np.cos(2 * mid), xz, psi, feet, g.reach)
    root = np.stack([xz[:, 0], y, xz[:, 1]], -1)
    yaw = -g.twist * np.cos(2 * np.pi * pl)
    rots = {"Hips": _mul(_rot("y", psi + yaw), _rot("x", 0.3 * g.lean)),  # lean mostly in the spine,
            "Spine": _mul(_rot("y", -0.6 * yaw), _rot("x", 0.7 * g.lean)),  # shoulders counter-rotate,
            "Chest": _rot("y", -0.6 * yaw), "Neck": _rot("x", -0.5 * g.lean), "Head": _rot("x", -0.5 * g.lean)}
    for s, sign, opposite in (("L", 1.0, pl + 0.5), ("R", -1.0, pl)):  # each arm swings with the other leg
        swing = g.arm_swing * np.cos(2 * np.pi * opposite)
        rots[f"UpperArm_{s}"] = _mul(_rot("z", sign * 0.14), _rot("x", -swing))
        rots[f"LowerArm_{s}"] = _rot("x", -g.elbow - 0.3 * swing * np.sign(g.arm_swing))
    return {"t": t, "root": root, "heading": psi, "rots": rots, "feet": feet}


def _leg_ik(hip: np.ndarray, target: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global thigh rotation (T, 3, 3) and knee flexion (T,) putting the ankle on ``target`` (cm).

    Analytic two-bone IK in the frame of the heading: the knee bends forward in the leg's vertical
    plane. Targets out of reach are pulled in (the ankle then falls short by that amount)."""
    d = target - hip
    c, s = np.cos(heading), np.sin(heading)
    dx, dy, dz = c * d[:, 0] - s * d[:, 2], d[:, 1], s * d[:, 0] + c * d[:, 2]
    n = np.sqrt(dx**2 + dy**2 + dz**2)
    k = np.clip(n, abs(THIGH - SHIN) + 1.0, 0.9999 * (THIGH + SHIN)) / n
    dx, dy, dz, n = dx * k, dy * k, dz * k, n * k
    knee = np.arccos(np.clip((n**2 - THIGH**2 - SHIN**2) / (2 * THIGH * SHIN), -1.0, 1.0))
    ay, az = -THIGH - SHIN * np.cos(knee), -SHIN * np.sin(knee)  # ankle in the thigh frame
    roll = np.arctan2(dx, -dy)
    pitch = np.arctan2(dz, -np.hypot(dx, dy)) - np.arctan2(az, ay)
    return _mul(_rot("y", heading), _rot("z", roll), _rot("x", pitch)), knee


def _legs(body: dict) -> dict:
    """Add UpperLeg/LowerLeg/Foot rotations so both feet follow their targets, flat on the floor."""
    R_pelvis, rots = body["rots"]["Hips"], body["rots"]
    offsets = {name: np.array(off) for name, _, off in JOINTS}
    for s in ("L", "R"):
        target, foot_yaw = body["feet"][s]
        hip = body["root"] + R_pelvis @ offsets[f"UpperLeg_{s}"]
        G, knee = _leg_ik(hip, target, body["heading"])
        rots[f"UpperLeg_{s}"] = np.swapaxes(R_pelvis, -1, -2) @ G
        rots[f"LowerLeg_{s}"] = _rot("x", knee)
        rots[f"Foot_{s}"] = np.swapaxes(G @ rots[f"LowerLeg_{s}"], -1, -2) @ _rot("y", foot_yaw)
    return body


# --------------------------------------------------------------------------------------- contents
def _arm_gesture(body: dict, content: str, e: np.ndarray, style: Style) -> None:
    """Raise (raise-up-*) or wave (wave-*, bye) the named arm(s) as the envelope ``e`` goes 0 -> 1 -> 0."""
    t, rots, words = body["t"], body["rots"], content.split("-")  # "bye" waves the right hand
    for s in ("L", "R") if "both" in words else ("L",) if "left" in words else ("R",):
        sign = 1.0 if s == "L" else -1.0
        if content.startswith("raise-up"):  # sideways and up to almost vertical (z first: no gimbal lock)
            up = 2.7 * (0.8 + 0.2 * min(style.amplitude, 1.2))
            rots[f"UpperArm_{s}"] = _mul(_rot("z", sign * (0.14 + e * up)), _rot("x", -0.25 * e))
            rots[f"LowerArm_{s}"] = _rot("z", sign * 0.15 * e) @ _rot("x", -0.2 * (1 - e))
        else:  # upper arm out and a little up, forearm up and waving side to side at ~2 Hz
            w = np.sin(2 * np.pi * 2.0 * style.tempo * t) * style.amplitude
            rots[f"UpperArm_{s}"] = _mul(_rot("z", sign * (0.14 + e * 1.85)), _rot("x", -0.3 * e))
            rots[f"LowerArm_{s}"] = _rot("z", sign * e * (0.75 + 0.4 * w))
            rots[f"Hand_{s}"] = _rot("z", sign * e * 0.25 * w)


def _bow(body: dict, e: np.ndarray, style: Style) -> None:
    """Bend forward from the hips and spine (about 55 degrees at the bottom), arms hanging, feet planted."""
    depth, rots = e * (0.8 + 0.2 * style.amplitude), body["rots"]
    rots["Hips"] = rots["Hips"] @ _rot("x", 0.25 * depth)
    rots["Spine"] = rots["Spine"] @ _rot("x", 0.4 * depth)
    rots["Chest"] = rots["Chest"] @ _rot("x", 0.3 * depth)
    rots["Neck"] = _rot("x", 0.1 * depth)
    fwd = np.stack([np.sin(body["heading"]), 0 * e, np.cos(body["heading"])], -1)
    body["root"] = body["root"] - (7.0 * depth)[:, None] * fwd - (4.0 * depth)[:, None] * np.array([0, 1.0, 0])
    for s, sign in (("L", 1.0), ("R", -1.0)):
        rots[f"UpperArm_{s}"] = _mul(_rot("z", sign * 0.14), _rot("x", -0.85 * depth))


def _dance_arms(body: dict, cadence: float) -> None:
    """Both arms up over the head, swaying in time with the steps."""
    for s, sign, shift in (("L", 1.0, 0.0), ("R", -1.0, np.pi)):
        sway = 0.35 * np.sin(2 * np.pi * cadence * body["t"] + shift)
        body["rots"][f"UpperArm_{s}"] = _rot("z", sign * (2.2 + sway))
        body["rots"][f"LowerArm_{s}"] = _rot("z", sign * 0.3)


def animate(content: str, style: str, seconds: float, rng: np.random.Generator, fps: float = FPS) -> dict:
    """One clip: {"root": (T, 3) pelvis position in cm, "rots": {joint: (T, 3, 3) local rotation}}.

    Joints missing from "rots" keep the rest pose. Raises KeyError for contents or styles that have no
    generator (see `CLIPS` for the ones that do)."""
    st = STYLES[style]
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    g = GAITS.get(content, Gait())
    g = replace(g, speed=g.speed * st.speed, cadence=g.cadence * st.tempo, lean=g.lean + st.lean,
                arm_swing=g.arm_swing * st.amplitude, bob=g.bob * min(st.amplitude, 1.2))
    if content == "dance-short":
        g = replace(g, turn=float(rng.choice([-1.0, 1.0])) * 2 * np.pi / t[-1])
    elif not (content in GAITS or content == "bow" or content.startswith(("wave", "raise-up", "bye"))):
        raise KeyError(f"no synthetic motion for content {content!r}")
    body = _body(t, g, rng)
    rise = 0.7 / st.tempo
    e = _envelope(t, (0.2, 0.2 + rise), (t[-1] - 0.3 - rise, t[-1] - 0.3))
    if content == "bow":
        _bow(body, e, st)
    elif content == "dance-short":
        _dance_arms(body, g.cadence)
    elif content not in GAITS:
        _arm_gesture(body, content, e, st)
    return _legs(body)


# --------------------------------------------------------------------------------------- BVH files
def hierarchy_text() -> str:
    """The BVH HIERARCHY section (tabs, 6 channels per joint, zero End Sites), as Bandai writes it."""
    channels = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation "
    children = {name: [c for c, p, _ in JOINTS if p == name] for name, _, _ in JOINTS}
    offsets = {name: off for name, _, off in JOINTS}
    lines = ["HIERARCHY"]

    def emit(name: str, depth: int) -> None:
        tab = "\t" * depth
        lines.extend([f"{tab}{'ROOT' if depth == 0 else 'JOINT'} {name}", f"{tab}{{",
                      f"{tab}\tOFFSET " + " ".join(repr(float(v)) for v in offsets[name]), f"{tab}\t{channels}"])
        for child in children[name]:
            emit(child, depth + 1)
        if not children[name]:
            lines.extend([f"{tab}\tEnd Site", f"{tab}\t{{", f"{tab}\t\tOFFSET 0.0 0.0 0.0", f"{tab}\t}}"])
        lines.append(f"{tab}}}")

    emit(JOINTS[0][0], 0)
    return "\n".join(lines) + "\n"


def bvh_text(clip: dict, fps: float = FPS) -> str:
    """A whole BVH file for a clip from `animate`: 22 joints x 6 channels per frame, centimetres."""
    root, rots = clip["root"], clip["rots"]
    T = root.shape[0]
    cols = []
    for name, _, off in JOINTS:
        pos = np.zeros((T, 3)) if name == "joint_Root" else root if name == "Hips" else np.tile(off, (T, 1))
        cols += [pos, _euler_zxy_deg(np.broadcast_to(rots.get(name, np.eye(3)), (T, 3, 3)))]
    buf = io.StringIO()
    np.savetxt(buf, np.concatenate(cols, axis=1), fmt="%.5f")
    return f"{hierarchy_text()}MOTION\nFrames:\t{T}\nFrame Time:\t{1.0 / fps:.7f}\n{buf.getvalue()}"


def clip_ids() -> list[tuple[int, str, str, int]]:
    """(dataset number, content, style, take) of every synthetic clip, in writing order."""
    return [(n, c, s, take) for n, (contents, styles, takes) in CLIPS.items()
            for c in contents for s in styles for take in range(1, takes + 1)]


def write_synthetic_bandai(root: str | Path, seed: int = 0) -> Path:
    """Write the synthetic dataset under ``root`` (created if needed; files of the same names are
    replaced) and return ``root``. ``seed`` changes every clip's take-to-take variations.

    About 60 clips of 3-9 s at 30 fps: per dataset folder the real ``cfg`` label files, and per clip a
    gzipped BVH (fixed gzip time stamp, so the bytes are reproducible) and its JSON twin."""
    root = Path(root)
    for n, (contents, styles) in LABELS.items():
        cfg = root / f"Bandai-Namco-Research-Motiondataset-{n}" / "cfg"
        cfg.mkdir(parents=True, exist_ok=True)
        (cfg / "content_label.txt").write_text("\n".join(f"dataset-{n}_{c}" for c in contents) + "\n")
        (cfg / "style_label.txt").write_text("\n".join(f"dataset-{n}_{s}" for s in styles) + "\n")
        (cfg.parent / "data").mkdir(exist_ok=True)
    for n, content, style, take in clip_ids():
        clip_id = f"dataset-{n}_{content}_{style}_{take:03d}"
        rng = np.random.default_rng(zlib.crc32(f"{seed}/{clip_id}".encode()))
        seconds = PINNED_DURATION_S.get(clip_id) or DURATION_S.get(content, 3.0) * rng.uniform(0.9, 1.1)
        text = bvh_text(animate(content, style, seconds, rng))
        data = root / f"Bandai-Namco-Research-Motiondataset-{n}" / "data"
        (data / f"{clip_id}.bvh.gz").write_bytes(gzip.compress(text.encode(), compresslevel=1, mtime=0))
        twin = {"content": LABELS[n][0].index(content), "style": LABELS[n][1].index(style)}
        (data / f"{clip_id}.json").write_text(json.dumps(twin))
    (root / "README.md").write_text("Bandai Namco layout, written by kinema.data.synthetic: procedural, not mocap.\n")
    return root


if __name__ == "__main__":  # python -m kinema.data.synthetic OUT_DIR
    import sys

    if len(sys.argv) != 2:
        sys.exit("usage: python -m kinema.data.synthetic OUT_DIR")
    out = write_synthetic_bandai(sys.argv[1])
    print(f"wrote {len(clip_ids())} synthetic clips under {out}")
