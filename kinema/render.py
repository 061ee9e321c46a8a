"""Skeleton drawings of a `Motion`: a filmstrip PNG of evenly spaced poses, or an animated GIF.

Why a hand-made orthographic camera instead of mplot3d: projecting the joints ourselves onto a
camera plane gives an exact equal aspect, painter's-order depth sorting of the bones (near limbs over
far ones), clipping for free by 2D axes, and GIF frames that render several times faster.

The camera is chosen once per motion so that every frame is framed: it looks at the character's
front-right three-quarter side (mean facing from hips/shoulders, or the travel direction), 15 degrees
from above, at one scale for the whole clip. Panels follow the character (its smoothed ground
position) when it travels further than the frame could hold; the window size covers the largest pose
of the clip, so nothing is cropped. Drawn: a fading ground grid, the root's ground trajectory (past
solid, future dotted), ground shadows, bones coloured by side (blue left, red right, grey centre, named
as in kinema.naming), a head with a nose pointing where the body faces, planted feet (green) when
``motion.foot_contacts`` is set, and constraint targets.

Targets (``targets=``) are tuples ``(frame, position)`` or ``(frame, position, label)``: a 3-vector
is a world point in metres (e.g. a hand target), a 2-vector ``(x, z)`` a root waypoint on the ground.
``frame`` may be None (always relevant). Targets near the shown frame are drawn strong, others faint.
"""

from __future__ import annotations

import io
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinema import naming
from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError, SkeletonError
from kinema.render_bones import drawn_bones, helper_root

SIDE_COLOURS = {"L": "#1f6fd1", "R": "#e0452b", None: "#3c3c3c"}
CONTACT_COLOUR, TARGET_COLOUR, WAYPOINT_COLOUR = "#14a05a", "#c0158c", "#b26b00"
ELEVATION_DEG, YAW_DEG = 15.0, -50.0  # camera 15 degrees up, 50 degrees to the character's right
UP = np.array([0.0, 1.0, 0.0])


@dataclass
class _Target:
    frame: int | None
    pos: np.ndarray  # (3,) world, metres
    label: str
    ground: bool  # a 2D root waypoint drawn on the floor


def _parse_targets(targets, num_frames: int, floor: float) -> list[_Target]:
    """Validate user targets (see the module docstring) into world points."""
    out = []
    for item in targets or ():
        try:
            frame, pos, *rest = item
        except (TypeError, ValueError):
            raise KinemaError(f"target {item!r} must be (frame, position) or (frame, position, label)") from None
        if len(rest) > 1:
            raise KinemaError(f"target {item!r} has too many fields")
        if frame is not None and not (float(frame).is_integer() and 0 <= int(frame) < num_frames):
            raise KinemaError(f"target frame {frame!r} is outside the motion's {num_frames} frames")
        p = np.asarray(pos, dtype=np.float64).reshape(-1)
        if p.shape not in ((2,), (3,)) or not np.isfinite(p).all():
            raise KinemaError(f"target position {pos!r} must be finite (x, y, z) or a waypoint (x, z)")
        world = np.array([p[0], floor, p[1]]) if len(p) == 2 else p
        frame = None if frame is None else int(frame)
        out.append(_Target(frame, world, str(rest[0]) if rest else "", len(p) == 2))
    return out


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """Moving average along axis 0 with edge padding (keeps the length)."""
    if width <= 1 or len(x) < 3:
        return x
    pad = np.concatenate([np.repeat(x[:1], width // 2, 0), x, np.repeat(x[-1:], width - 1 - width // 2, 0)])
    c = np.cumsum(np.concatenate([np.zeros_like(x[:1]), pad]), 0)
    return (c[width:] - c[:-width]) / width


class _Scene:
    """Everything frame-independent: world joint positions, bones, camera, scale and frame windows."""

    def __init__(self, motion, targets=None):
        if not motion.is_finite():
            raise KinemaError("cannot render a motion with NaN or infinite values")
        sk = motion.skeleton
        self.fps, self.T = motion.fps, motion.num_frames
        self.P = motion.positions.detach().cpu().double().numpy()  # (T, J, 3)
        roles = sk.roles
        pelvis = roles.get("pelvis", 0)
        hidden = helper_root(sk, self.P, pelvis)
        self.shown = [j for j in range(sk.num_joints) if j not in hidden]
        self.bones = drawn_bones(sk, self.P, hidden)
        self.bone_colours = [SIDE_COLOURS[naming.split_side(sk.names[j])[0]] for _, j in self.bones]
        shown = self.P[:, self.shown]
        self.floor = float(shown[..., 1].min())
        spans = np.linalg.norm(shown.max(1) - shown.min(1), axis=-1)
        self.span = max(float(np.median(spans)), 0.2)  # ~1.5 m for an adult standing
        self.head = roles.get("head")
        self.neck = roles.get("neck", sk.parents[self.head] if self.head is not None else -1)
        if self.head is None or self.neck < 0 or self.head in hidden:
            self.head = None  # no head joint (or no joint below it): no head circle, no nose
        self.head_r = 0.065 * self.span
        self.contacts, self.contact_joints = None, []
        if motion.foot_contacts is not None:
            from kinema.motion.contacts import contact_joints

            try:
                self.contact_joints = contact_joints(sk)
                self.contacts = motion.foot_contacts.detach().cpu().numpy() > 0.5
            except SkeletonError:
                pass
        self.ground = self.P[:, pelvis].copy()
        self.ground[:, 1] = self.floor
        self.forward = self._facing(roles)
        self.targets = _parse_targets(targets, self.T, self.floor)
        self._camera()

    def _facing(self, roles) -> np.ndarray | None:
        """(T, 3) unit horizontal facing from the left-minus-right hips (+ shoulders), or None."""
        left = np.zeros((self.T, 3))
        for a, b in (("left_hip", "right_hip"), ("left_upper_arm", "right_upper_arm")):
            if a in roles and b in roles:
                left += self.P[:, roles[a]] - self.P[:, roles[b]]
        fwd = np.stack([-left[:, 2], np.zeros(self.T), left[:, 0]], -1)  # cross(left, up)
        n = np.linalg.norm(fwd, axis=-1, keepdims=True)
        return fwd / n if (n > 1e-6).all() else None

    def _camera(self) -> None:
        """Pick the view direction, then the per-frame follow windows and the whole-motion window."""
        heading = self.forward.sum(0) if self.forward is not None else np.zeros(3)
        if np.linalg.norm(heading) < 0.2 * self.T:  # no consistent facing: use the travel direction
            heading = self.ground[-1] - self.ground[0]
        if np.linalg.norm(heading[[0, 2]]) < 1e-6:
            heading = np.array([0.0, 0.0, 1.0])
        a = math.atan2(heading[0], heading[2]) + math.radians(YAW_DEG)
        e = math.radians(ELEVATION_DEG)
        to_cam = np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
        self.view = -to_cam
        right = np.cross(self.view, UP)
        right /= np.linalg.norm(right)
        self.basis = np.stack([right, np.cross(right, self.view)], 1)  # (3, 2): world -> screen (u, v)
        centre = _smooth(self.ground, max(1, round(0.6 * self.fps)))
        self.centre2d = self.project(centre)  # (T, 2) where follow panels are centred
        pts = [self.project(self.P[:, self.shown]), self.project(self._shadow(self.P[:, self.shown]))]
        if self.head is not None:
            hc = self.project(self.head_centre(np.arange(self.T)))[:, None]
            pts += [hc + [0, self.head_r], hc - [self.head_r, 0], hc + [self.head_r, 0]]
        rel = np.concatenate([p - self.centre2d[:, None] for p in pts], 1)
        m = 0.07 * self.span
        half_w = np.abs(rel[..., 0]).max() + m
        lo, hi = rel[..., 1].min() - m, rel[..., 1].max() + m
        lo -= 0.1 * (hi - lo)  # room for the caption under the feet
        self.follow_box = np.array([-half_w, half_w, lo, hi])  # relative to centre2d[t]
        allp = np.concatenate([p.reshape(-1, 2) for p in pts] + [self.project(np.array([t.pos for t in self.targets]))
                                                                 if self.targets else np.zeros((0, 2))])
        self.fixed_box = np.array([allp[:, 0].min() - m, allp[:, 0].max() + m,
                                   allp[:, 1].min() - m - 0.1 * (hi - lo), allp[:, 1].max() + m])

    def project(self, x: np.ndarray) -> np.ndarray:
        return x @ self.basis

    def depth(self, x: np.ndarray) -> np.ndarray:
        return x @ self.view

    def _shadow(self, x: np.ndarray) -> np.ndarray:
        s = x.copy()
        s[..., 1] = self.floor
        return s

    def head_centre(self, t) -> np.ndarray:
        d = self.P[t, self.head] - self.P[t, self.neck]
        d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
        return self.P[t, self.head] + 1.1 * self.head_r * d

    def follows(self) -> bool:
        """Follow the character when the whole motion is much wider or taller than one pose."""
        fw, fh = self.follow_box[1] - self.follow_box[0], self.follow_box[3] - self.follow_box[2]
        return self.fixed_box[1] - self.fixed_box[0] > 1.6 * fw or self.fixed_box[3] - self.fixed_box[2] > 1.4 * fh

    def window(self, t: int, follow: bool, aspect: float) -> tuple[float, float, float, float]:
        """Axes limits (x0, x1, y0, y1) for frame t, widened to the panel's width/height aspect."""
        b = self.follow_box + np.repeat(self.centre2d[t], 2) if follow else self.fixed_box
        cx, cy, w, h = (b[0] + b[1]) / 2, (b[2] + b[3]) / 2, b[1] - b[0], b[3] - b[2]
        w, h = max(w, h * aspect), max(h, w / aspect)
        return cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2

    def natural_aspect(self, follow: bool, lo: float, hi: float) -> float:
        b = self.follow_box if follow else self.fixed_box
        return float(np.clip((b[1] - b[0]) / (b[3] - b[2]), lo, hi))

    def grid(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        """Ground grid segments (S, 2, 2) around frame t's position, and their fading alphas (S,)."""
        step = 10 ** math.floor(math.log10(self.span / 3))
        step *= 5 if self.span / 3 / step >= 5 else 2 if self.span / 3 / step >= 2 else 1
        radius = 1.4 * self.span
        c = self.ground[t]
        segs = []
        for ax in (0, 2):
            other = 2 - ax
            lines = np.arange(math.ceil((c[ax] - radius) / step), math.floor((c[ax] + radius) / step) + 1) * step
            cuts = np.arange(math.floor((c[other] - radius) / step), math.ceil((c[other] + radius) / step) + 1)
            cuts = cuts * step
            a = np.zeros((len(lines), len(cuts) - 1, 2, 3))
            a[..., 1] = self.floor
            a[..., ax] = lines[:, None, None]
            a[..., 0, other], a[..., 1, other] = cuts[:-1], cuts[1:]
            segs.append(a.reshape(-1, 2, 3))
        segs = np.concatenate(segs)
        dist = np.linalg.norm(segs.mean(1)[:, [0, 2]] - c[[0, 2]], axis=-1)
        return self.project(segs), 0.45 * np.clip(1 - dist / radius, 0, 1) ** 1.5


class _Panel:
    """The artists of one view; `update(t)` poses them for frame t (used once per filmstrip panel,
    once per GIF frame)."""

    def __init__(self, scene: _Scene, ax, follow: bool, aspect: float, target_tolerance: float, lw: float):
        from matplotlib.collections import LineCollection
        from matplotlib.lines import Line2D
        from matplotlib.patches import Circle

        self.s, self.ax, self.follow, self.aspect, self.tol = scene, ax, follow, aspect, target_tolerance
        ax.set_axis_off()
        ax.set_aspect("equal", adjustable="datalim")
        self.grid = ax.add_collection(LineCollection([], colors="#7a869a", linewidths=0.8, zorder=0))
        traj = scene.project(scene.ground)
        self.future = ax.add_line(Line2D(traj[:, 0], traj[:, 1], color="#9aa3b0", lw=1.2, ls=":", zorder=1))
        self.past = ax.add_line(Line2D([], [], color="#5d6673", lw=1.6, zorder=1))
        self.traj = traj
        self.shadow = ax.add_collection(LineCollection([], colors=(0.2, 0.25, 0.3, 0.10), linewidths=lw, zorder=2,
                                                       capstyle="round"))
        self.bones = ax.add_collection(LineCollection([], linewidths=lw, zorder=3, capstyle="round"))
        self.head = None
        if scene.head is not None:
            self.head = ax.add_patch(Circle((0, 0), scene.head_r, fc="#f2f2f2", ec=SIDE_COLOURS[None], lw=lw * 0.6,
                                            zorder=4))
            self.nose = ax.add_line(Line2D([], [], color=SIDE_COLOURS[None], lw=lw * 0.6, zorder=4.1,
                                           solid_capstyle="round"))
        self.feet = ax.scatter([], [], s=(lw * 3.2) ** 2, c=CONTACT_COLOUR, ec="white", lw=0.8, zorder=5)
        tg = scene.targets
        txy = scene.project(np.array([t.pos for t in tg])) if tg else np.zeros((0, 2))
        self.tpts = ax.scatter(txy[:, 0], txy[:, 1], s=(lw * 4) ** 2, marker="X", zorder=6, lw=0.6, ec="white",
                               c=[WAYPOINT_COLOUR if t.ground else TARGET_COLOUR for t in tg] or None)
        drops = [[scene.project(t.pos), scene.project(scene._shadow(t.pos))] for t in tg if not t.ground]
        self.tdrop = ax.add_collection(LineCollection(drops, colors=TARGET_COLOUR, linewidths=0.8, linestyles="--",
                                                      zorder=5.5))
        self.tlabels = [ax.annotate(t.label, scene.project(t.pos), xytext=(5, 5), textcoords="offset points",
                                    fontsize=7, color=WAYPOINT_COLOUR if t.ground else TARGET_COLOUR, zorder=7)
                        for t in tg]
        self.caption = ax.text(0.5, 0.015, "", transform=ax.transAxes, ha="center", va="bottom", fontsize=8,
                               color="#333333")

    def update(self, t: int) -> None:
        s = self.s
        x0, x1, y0, y1 = s.window(t, self.follow, self.aspect)
        self.ax.set_xlim(x0, x1)
        self.ax.set_ylim(y0, y1)
        segs, alpha = s.grid(t)
        self.grid.set_segments(segs)
        self.grid.set_alpha(None)
        self.grid.set_color([(0.48, 0.53, 0.6, a) for a in alpha])
        self.past.set_data(self.traj[: t + 1, 0], self.traj[: t + 1, 1])
        self.future.set_data(self.traj[t:, 0], self.traj[t:, 1])
        pose = s.P[t]
        ends = np.stack([pose[[a for a, _ in s.bones]], pose[[b for _, b in s.bones]]], 1)  # (B, 2, 3)
        order = np.argsort(-s.depth(ends.mean(1)))  # far bones first
        self.bones.set_segments(s.project(ends)[order])
        self.bones.set_color([s.bone_colours[i] for i in order])
        self.shadow.set_segments(s.project(s._shadow(ends)))
        if self.head is not None:
            hc = s.head_centre(t)
            self.head.set_center(s.project(hc))
            if s.forward is not None:
                nose = s.project(np.stack([hc + 0.5 * s.head_r * s.forward[t], hc + 1.7 * s.head_r * s.forward[t]]))
                self.nose.set_data(nose[:, 0], nose[:, 1])
        if s.contacts is not None:
            planted = [j for j, on in zip(s.contact_joints, s.contacts[t], strict=True) if on]
            self.feet.set_offsets(s.project(pose[planted]) if planted else np.zeros((0, 2)))
        if s.targets:
            near = [tg.frame is None or abs(tg.frame - t) <= self.tol for tg in s.targets]
            self.tpts.set_alpha(None)
            rgba = self.tpts.get_facecolor()
            rgba[:, 3] = [1.0 if n else 0.3 for n in near]
            self.tpts.set_facecolor(rgba)
            for lab, n in zip(self.tlabels, near, strict=True):
                lab.set_alpha(1.0 if n else 0.35)
        self.caption.set_text(f"t = {t / s.fps:.2f} s   (frame {t})")


def _legend(fig, scene: _Scene, title: str | None, top: float, rows: int = 1) -> None:
    """Title at the top left and a colour key, inside a strip of ``top`` figure units at the top;
    with ``rows=2`` (narrow GIFs) the key goes on a second line under the title."""
    from matplotlib.lines import Line2D

    y_title = 1 - top / (2 * rows)
    if title:
        fig.text(0.01, y_title, title, ha="left", va="center", fontsize=10 if len(title) <= 40 else 8,
                 weight="bold")
    keys = [Line2D([], [], color=SIDE_COLOURS["L"], lw=3, label="left"),
            Line2D([], [], color=SIDE_COLOURS["R"], lw=3, label="right")]
    if scene.contacts is not None:
        keys.append(Line2D([], [], color=CONTACT_COLOUR, marker="o", ls="", label="foot contact"))
    if any(not t.ground for t in scene.targets):
        keys.append(Line2D([], [], color=TARGET_COLOUR, marker="X", ls="", label="target"))
    if any(t.ground for t in scene.targets):
        keys.append(Line2D([], [], color=WAYPOINT_COLOUR, marker="X", ls="", label="waypoint"))
    y_key = y_title if rows == 1 else 1 - 3 * top / 4
    loc, x = ("center right", 0.995) if rows == 1 else ("center left", 0.0)
    fig.legend(handles=keys, loc=loc, bbox_to_anchor=(x, y_key), ncol=len(keys), frameon=False, fontsize=8,
               handlelength=1.6, columnspacing=1.2, handletextpad=0.5)


def _check_out(path, suffix: str) -> Path:
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise KinemaError(f"{path}: output must end in {suffix}")
    if path.is_dir():
        raise KinemaError(f"{path}: is a folder")
    return path


def render_filmstrip(motion, path, frames: int = 8, targets=None, title: str | None = None) -> Path:
    """Draw ``frames`` evenly spaced poses side by side into a PNG at ``path`` (written atomically)."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    path = _check_out(path, ".png")
    if not 1 <= int(frames) <= 48:
        raise KinemaError(f"--frames must be between 1 and 48, got {frames}")
    scene = _Scene(motion, targets)
    idx = np.unique(np.linspace(0, scene.T - 1, min(int(frames), scene.T)).round().astype(int))
    aspect = scene.natural_aspect(True, 0.5, 1.4)
    ph, gap, top = 3.2, 0.06, 0.38  # inches: panel height, gap between panels, title strip
    pw = ph * aspect
    fw, fh = len(idx) * pw + (len(idx) + 1) * gap, ph + top + gap
    fig = Figure(figsize=(max(fw, 4.5), fh), dpi=100, facecolor="white")
    x0 = (max(fw, 4.5) - fw) / 2
    tol = max(1.0, (idx[1] - idx[0]) / 2 if len(idx) > 1 else scene.T)
    for k, t in enumerate(idx):
        rect = [(x0 + gap + k * (pw + gap)) / fig.get_figwidth(), gap / fh, pw / fig.get_figwidth(), ph / fh]
        ax = fig.add_axes(rect)
        _Panel(scene, ax, True, aspect, tol, lw=2.6).update(int(t))
        ax.add_patch(Rectangle((0, 0), 1, 1, transform=ax.transAxes, fill=False, ec="#d5d9df", lw=0.8, zorder=10))
    _legend(fig, scene, title, top / fh)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", facecolor="white")
    atomic_write_bytes(path, buf.getvalue())
    return path


def render_gif(motion, path, fps: float | None = None, targets=None, title: str | None = None) -> Path:
    """Animate the motion into a looping GIF at ``path`` (``fps`` default: the motion's, at most 20)."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = _check_out(path, ".gif")
    fps = min(motion.fps, 20.0) if fps is None else float(fps)
    if not (math.isfinite(fps) and 0 < fps <= 60):
        raise KinemaError(f"GIF fps must be in (0, 60], got {fps}")
    scene = _Scene(motion, targets)
    times = np.arange(0.0, (scene.T - 1) / scene.fps + 1e-9, 1.0 / fps)
    idx = np.minimum(np.round(times * scene.fps).astype(int), scene.T - 1)
    follow = scene.follows()
    aspect = scene.natural_aspect(follow, 0.6, 1.8)
    side = 4.6
    w, h = (side, side / aspect) if aspect >= 1 else (side * aspect, side)
    w = max(w, 4.0)
    rows = 1 if w >= 6 else 2
    top = 0.3 * rows + 0.06
    fig = Figure(figsize=(w, h + top), dpi=80, facecolor="white")
    FigureCanvasAgg(fig)
    ax = fig.add_axes([0, 0, 1, h / (h + top)])
    panel = _Panel(scene, ax, follow, w / h, max(1.0, 0.1 * scene.fps), lw=2.4)
    _legend(fig, scene, title, top / (h + top), rows)
    anim = FuncAnimation(fig, lambda i: panel.update(int(idx[i])), frames=len(idx), blit=False,
                         cache_frame_data=False, repeat=False)
    with tempfile.TemporaryDirectory(prefix="kinema-render-") as tmp:
        out = Path(tmp) / "anim.gif"
        anim.save(out, writer=PillowWriter(fps=fps), dpi=80)
        atomic_write_bytes(path, out.read_bytes())
    return path
