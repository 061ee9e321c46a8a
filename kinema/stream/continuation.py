"""`MotionStream`: an endless motion made window by window through a pipeline's ``generate(request)``.

Each window (``window_seconds`` long, ``steps`` DDIM steps) is generated in a local frame whose first
root stands over the origin, turned so that the context's last frame faces +Z (a walk turned to +X and
then told to bow stayed bent over 45-57 deg for 10 s in a frame that was not turned; turned, it bows
and stands up again like an unturned one). Its first `CONTEXT_SECONDS` are the last frames generated
so far, imposed as ``fullbody`` keyframes, so it continues the motion; the controls (prompt, steering
path, targets: kinema.stream.controls) constrain the rest. Its next `BLEND_SECONDS` are cross-faded
from the previous window (`SKIP_SECONDS` after the context may be left out first; 0 by default)
(kinema.stream.frames.stitch: rotations slerped, the root's ground velocity blended), and the root's
ground velocity is low-passed over the next `EASE_SECONDS` (kinema.stream.frames.ease_root_velocity:
the denoiser's first free frames after the context jolt the pelvis). While steering,
the window is turned to face along its path; every window is lifted or lowered onto the first one's
ground level (at most `FLOOR_STEP` a window). Windows are not post-processed, except while a target
is held: after context keyframes the raw denoiser leaves a hand target 25-30 cm off (a lone clip:
15 cm); post-processing hits it exactly but costs about 1 s a window.

Frames are handed out in order (``next_frames(n)`` or iteration). A command (``set_prompt``, ``steer``,
``target``, ``clear``) cuts the frames not yet handed out back to ``lookahead`` seconds after the last
one handed out and regenerates from there: the first frame that obeys it (the new window's weight
past one half) is ``lookahead + SKIP_SECONDS + BLEND_SECONDS / 2`` seconds of motion later (0.25 s by
default: 3 + 0 + 2 frames), whatever the window length. The first window after a prompt switch runs with a stronger
text guidance (`SWITCH_GUIDANCE`). Frames already handed out are dropped from memory (the last
`HISTORY_FRAMES` are kept for the smoothed root), so a stream's memory does not grow.

The stream is not thread-safe: a face that generates on a worker thread queues commands and applies
them between ``next_frames`` calls (kinema.server.stream does).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import torch

from kinema.errors import KinemaError
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time
from kinema.stream.bodies import HumanBody, RigBody
from kinema.stream.controls import DEFAULT_SPEED, MAX_PROMPT_CHARS, Controls, Steer, Target, WindowFrame
from kinema.stream.frames import StreamFrames, ease_root_velocity, ground_level, shifted, stitch, turn_xz, turned

#: default seconds of one window (the denoiser sees at most the model's window_seconds)
WINDOW_SECONDS = 3.0
#: default seconds of generated motion kept ahead of what was handed out when a command arrives
LOOKAHEAD_SECONDS = 0.15
#: default DDIM steps of a streamed window
STREAM_STEPS = 10
#: seconds of the previous motion imposed on a window's first frames
CONTEXT_SECONDS = 0.2
#: seconds of a window's own frames after its context that are not used (the previous window's are
#: kept there). The denoiser's first free frames after keyframes lag them (pelvis speed 2.9 -> 1.3 m/s
#: in one frame on a walk, recovering over ~0.3 s), which skipping 0.2 s hid while the cross-fade
#: blended root *positions*; with the root's velocity blended (`stitch`) it is not needed, and skipping
#: dropped a window's own start: a wave -> jog switch in a 10-min stream made a 474 m/s^2 pop at the
#: seam (the windows' own largest: 282). 0 s: the seams of the first 100 s of
#: examples/streams/ten_minutes.jsonl peak at 230 m/s^2 and the latency falls from 0.45 to 0.25 s.
SKIP_SECONDS = 0.0
#: seconds over which a window is cross-faded from the previous one's provisional frames
BLEND_SECONDS = 0.25
#: seconds after a seam over which the root's ground velocity is low-passed (`ease_root_velocity`),
#: the Gaussian's width in frames, and the final frames before the seam it reads. A window made twice
#: (`ROOT_FROM_FIRST_PASS`) is eased over its whole length: the stronger guidance leaves its pelvis
#: stuttering around the imposed root path (a wave -> jog: 2.5, 1.7, 0.6, 3.9, 2.4 m/s on consecutive
#: frames, 65 m/s^2 against the windows' own 29 over 120 s of `kinema bench stream`'s cycle)
EASE_SECONDS = 0.5
EASE_SIGMA_FRAMES = 1.5
EASE_HISTORY = 8
#: frames kept before the next context (the smoothed root is measured over them)
HISTORY_FRAMES = 40
#: Gaussian (seconds) over which a steered window's facing error is smoothed before it is turned away
FACING_SIGMA_SECONDS = 0.3
#: guidance (w_text, w_constr) of the first window after a prompt switch: the context keyframes of
#: the old behaviour outweigh the new text at the model's (2, 2) (walk -> bow, seeds 0/1, 10 steps:
#: trunk lean 30/35 degrees; with (4, 2): 40/39, lone bows 41)
SWITCH_GUIDANCE = (4.0, 2.0)
#: whether the first window after a prompt switch takes its root path from a first pass at the
#: model's own guidance (human model, not while steering): with `SWITCH_GUIDANCE` alone a jog after a
#: wave burst from 0 to 6.1-6.5 m/s within the window (the model's guidance: 4.3-4.4 m/s), since the
#: stronger text weight exaggerates the root's speed as much as the pose
ROOT_FROM_FIRST_PASS = True
#: largest height correction of one window, metres (kinema.stream.frames.ground_level)
FLOOR_STEP = 0.02
#: most frames one ``next_frames`` call may ask for
MAX_FRAMES_PER_CALL = 100_000


@dataclass
class CommandRecord:
    """One command: what it was, the stream frame it arrived at, the first frame that obeys it (the
    new window's weight past one half) and when (wall clock, ``time.perf_counter``) it arrived and
    that frame was generated."""

    kind: str
    value: Any
    issued_frame: int
    effective_frame: int
    fps: float
    issued_wall: float
    ready_wall: float | None = None

    @property
    def latency_seconds(self) -> float:
        """Seconds of motion from the command to the first frame that obeys it."""
        return (self.effective_frame - self.issued_frame) / self.fps

    @property
    def wall_seconds(self) -> float | None:
        """Wall seconds from the command until that frame was generated (None: not yet)."""
        return None if self.ready_wall is None else self.ready_wall - self.issued_wall

    def to_json(self) -> dict:
        wall = self.wall_seconds
        return {"kind": self.kind, "value": self.value, "issued_frame": self.issued_frame,
                "issued_seconds": round(self.issued_frame / self.fps, 4),
                "effective_frame": self.effective_frame, "latency_seconds": round(self.latency_seconds, 4),
                "wall_seconds": None if wall is None else round(wall, 4)}


@dataclass
class WindowStats:
    """Timings of one window (wall seconds): the pipeline's sampling and post-processing, the rest
    (request building, constraint encoding, stitching) as ``other``."""

    first_frame: int
    new_frames: int
    sampling: float
    postprocess: float
    other: float

    @property
    def wall(self) -> float:
        return self.sampling + self.postprocess + self.other


@dataclass
class StreamSettings:
    """A stream's window geometry in frames at the model's fps, and its DDIM steps and seed."""

    fps: float
    window: int
    context: int
    skip: int
    blend: int
    lookahead: int
    steps: int
    seed: int = 0
    #: whether each window is as long as the model makes the current prompt at once (``model.window_for``)
    #: rather than ``window`` frames (which it stays for a prompt the model names no window for)
    window_from_prompt: bool = False

    @classmethod
    def checked(cls, model, window_seconds: float, lookahead: float, steps: int | None, seed: int,
                window_from_prompt: bool = False) -> StreamSettings:
        fps = float(model.fps)
        context, blend = max(2, round(CONTEXT_SECONDS * fps)), max(1, round(BLEND_SECONDS * fps))
        skip = round(SKIP_SECONDS * fps)
        longest = float(model.window_seconds)
        shortest = (context + skip + blend + max(2, round(0.5 * fps))) / fps
        if not _number(window_seconds) or not shortest <= window_seconds <= longest:
            raise KinemaError(f"window_seconds must be in [{shortest:g}, {longest:g}] (the model's window), "
                              f"got {window_seconds!r}")
        window = round(window_seconds * fps)
        if not _number(lookahead) or not 0 <= lookahead <= window_seconds:
            raise KinemaError(f"lookahead must be in [0, {window_seconds:g}] seconds, got {lookahead!r}")
        steps = STREAM_STEPS if steps is None else steps
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= model.max_steps:
            raise KinemaError(f"steps must be an integer in [1, {model.max_steps}], got {steps!r}")
        return cls(fps, window, context, skip, blend, round(lookahead * fps), steps, seed, window_from_prompt)

    def window_for(self, model, prompt: str) -> int:
        """Frames of a window of ``prompt``: ``window``, or with ``window_from_prompt`` the model's window for
        it (within the shortest window and the model's)."""
        seconds = model.window_for(prompt) if self.window_from_prompt else None
        if seconds is None:
            return self.window
        shortest = self.context + self.skip + self.blend + max(2, round(0.5 * self.fps))
        return max(shortest, min(round(seconds * self.fps), round(float(model.window_seconds) * self.fps)))


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


class MotionStream:
    """An endless motion following its controls; create it with `open_stream`."""

    def __init__(self, model, request, settings: StreamSettings, body: HumanBody | RigBody):
        self.model = model
        self.request = request
        self.settings = settings
        self.body = body
        base_prompt = "" if request is None else request.prompt
        self.controls = Controls(prompt=base_prompt)
        self.commands: list[CommandRecord] = []
        self.windows: list[WindowStats] = []
        self._motion: Motion | None = None  # stream frames [_offset, _offset + num_frames)
        self._offset = 0
        self._tail = 0  # provisional frames at the end of _motion (a later window blends over them)
        self._emitted = 0
        self._window_index = 0
        self._floor: float | None = None  # ground level of the first window, metres
        self._switch_windows = 0  # windows still to generate with the prompt-switch guidance
        self._path_headings: torch.Tensor | None = None  # the steered path's heading per window frame

    # ------------------------------------------------------------------ state
    @property
    def fps(self) -> float:
        return self.settings.fps

    @property
    def skeleton(self):
        """The skeleton the frames are on: the human model's own, or the request's rig."""
        return self.body.skeleton

    @property
    def frames_out(self) -> int:
        """Frames handed out so far."""
        return self._emitted

    @property
    def buffered_frames(self) -> int:
        """Final frames generated and not yet handed out."""
        return self._final_end() - self._emitted

    def seams(self) -> list[tuple[int, int]]:
        """Stream frames ``[lo, hi)`` where each window was cross-faded into the previous one (the first
        `SKIP_SECONDS` after a window's context are the previous window's own frames)."""
        s = self.settings
        return [(w.first_frame + s.skip, w.first_frame + s.skip + s.blend) for w in self.windows[1:]]

    def _final_end(self) -> int:
        return self._offset if self._motion is None else self._offset + self._motion.num_frames - self._tail

    # ------------------------------------------------------------------ commands
    def set_prompt(self, text: str) -> CommandRecord:
        """Switch what the character does (from ``lookahead`` seconds on)."""
        if not isinstance(text, str) or len(text) > MAX_PROMPT_CHARS:
            raise KinemaError(f"prompt must be a string of at most {MAX_PROMPT_CHARS} characters, "
                              f"got {type(text).__name__}")
        self.controls.prompt = text
        self._switch_windows = 1
        return self._command("prompt", text)

    def steer(self, direction_deg: float | None = None, speed: float = DEFAULT_SPEED) -> CommandRecord:
        """Move towards world heading ``direction_deg`` (0 = +Z, 90 = +X; None: straight on) at ``speed`` m/s."""
        steer = Steer.checked(direction_deg, speed)
        if steer.direction_deg is None and self.controls.steer is not None:
            steer = Steer(self.controls.steer.direction_deg, steer.speed)
        self.controls.steer = steer
        return self._command("steer", {"direction_deg": direction_deg, "speed": speed})

    def target(self, joint: str, position) -> CommandRecord:
        """Put ``joint`` (a name or role, e.g. ``right_hand``) at world ``position`` (metres) and hold it."""
        skel = self.skeleton
        t = Target.checked(joint, position, skel.names, skel.roles)
        self.controls.targets[t.joint] = t
        return self._command("target", {"joint": t.joint, "position": list(t.position)})

    def clear(self) -> CommandRecord:
        """Drop steering and targets (the prompt stays)."""
        self.controls.steer = None
        self.controls.targets.clear()
        return self._command("clear", None)

    def _command(self, kind: str, value) -> CommandRecord:
        """Cut the frames not handed out back to the lookahead and log the command."""
        s = self.settings
        cut = min(self._final_end(), self._emitted + s.lookahead)
        if self._motion is not None and cut < self._offset + self._motion.num_frames:
            keep = min(self._offset + self._motion.num_frames, cut + s.skip + s.blend) - self._offset
            self._motion = self._motion.crop(0, keep)
            self._tail = self._offset + keep - cut
        effective = cut + (s.skip + s.blend // 2 if self._motion is not None else 0)
        record = CommandRecord(kind, value, self._emitted, effective, s.fps, time.perf_counter())
        self.commands.append(record)
        return record

    # ------------------------------------------------------------------ frames
    def next_frames(self, n: int) -> StreamFrames:
        """The next ``n`` frames (generating windows as needed)."""
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_FRAMES_PER_CALL:
            raise KinemaError(f"next_frames: n must be an integer in [1, {MAX_FRAMES_PER_CALL}], got {n!r}")
        while self._final_end() < self._emitted + n:
            self._extend()
        lo = self._emitted - self._offset
        frames = StreamFrames.of(self._motion.crop(lo, lo + n), self._emitted)
        self._emitted += n
        self._forget()
        return frames

    def __iter__(self) -> Iterator[StreamFrames]:
        """One frame at a time, for ever."""
        while True:
            yield self.next_frames(1)

    def _forget(self) -> None:
        """Drop handed-out frames that no window needs as context any more."""
        drop = self._emitted - max(self.settings.context, HISTORY_FRAMES) - self._offset
        if self._motion is not None and drop > 0 and drop < self._motion.num_frames - self._tail:
            self._motion = self._motion.crop(drop)
            self._offset += drop

    def _extend(self) -> None:
        """Generate the next window from the last final frames and stitch it on."""
        t0 = time.perf_counter()
        s = self.settings
        if self._motion is None:
            window, timings, _ = self._generate(None, None, None)
            self._floor = ground_level(window)
            self._motion, self._tail = window, s.skip + s.blend
            self._log_window(0, window.num_frames - self._tail, timings, t0)
            return
        end = self._final_end() - self._offset
        context = self._motion.crop(end - s.context, end)
        smooth = self._smoothed_root(end)
        frame = self._window_frame(context, smooth)
        local = turned(shifted(context, -frame.origin[0], -frame.origin[1]), -frame.yaw)
        local_smooth = turn_xz(smooth - torch.tensor(frame.origin), -frame.yaw)
        window, timings, made_twice = self._generate(local, local_smooth, frame)
        window = self._on_floor(self._face_path(window))
        window = shifted(turned(window, frame.yaw), *frame.origin).crop(s.context - 1)
        stitched = stitch(self._motion.crop(end - 1), window, s.skip, s.blend)
        before = self._motion.root_translation[max(0, end - EASE_HISTORY) : end, [0, 2]]
        ease = stitched.num_frames if made_twice else round(EASE_SECONDS * s.fps)
        stitched = ease_root_velocity(before, stitched, ease, EASE_SIGMA_FRAMES)
        self._motion = self._motion.crop(0, end).concatenate(stitched.to(self._motion.dtype))
        self._tail = s.skip + s.blend
        self._log_window(self._offset + end, stitched.num_frames - self._tail, timings, t0)

    def _smoothed_root(self, end: int) -> torch.Tensor:
        """The smoothed root x/z ``(C, 2)`` of the context frames before buffer frame ``end``: the pelvis
        under the representation's Gaussian, over the history kept and the provisional frames after it."""
        pelvis = self._motion.root_translation[:, [0, 2]].float()
        smooth = smooth_time(pelvis, DEFAULT_ROOT_SIGMA_SECONDS * self.fps)
        return smooth[end - self.settings.context : end]

    def _window_frame(self, context: Motion, smooth: torch.Tensor) -> WindowFrame:
        """Where the window starts: the context's first smoothed root as origin, turned so that its last
        frame faces +Z (the model then always starts as most training clips do), and the smoothed
        root's speed."""
        origin = self.body.origin(context, smooth)
        yaw = float(self.body.facing(context.crop(context.num_frames - 1))[0])
        speed = float((smooth[-1] - smooth[0]).norm()) * self.fps / max(1, context.num_frames - 1)
        frame = WindowFrame(origin, yaw, (0.0, 0.0), 0.0, speed, self.fps)
        return replace(frame, root_xz=frame.local_xz(float(smooth[-1, 0]), float(smooth[-1, 1])))

    def _on_floor(self, window: Motion) -> Motion:
        """The window moved up or down (by at most `FLOOR_STEP` metres) so that its ground level (the
        lowest joint in its stance frames) is the first window's: the denoiser's root height drifts by
        about a centimetre per window, which adds up over a long stream."""
        if self._floor is None:
            return window
        lift = max(-FLOOR_STEP, min(FLOOR_STEP, self._floor - ground_level(window.crop(self.settings.context))))
        return replace(window, root_translation=window.root_translation + torch.tensor([0.0, lift, 0.0]))

    def _face_path(self, window: Motion) -> Motion:
        """With steering, the window turned to face along its path (kinema.stream.frames.face_along)."""
        path = self._path_headings
        if path is None or not self.body.turns_to_path:
            return window
        first = self.settings.context - 1
        return self.body.face_path(window, path, first, FACING_SIGMA_SECONDS * self.fps)

    def _generate(self, context: Motion | None, smooth: torch.Tensor | None,
                  frame: WindowFrame | None) -> tuple[Motion, dict, bool]:
        """One window (local frame), the pipeline's timings and whether it was made twice. The first
        window after a prompt switch
        is made twice when not steered and the body can take a root path (the human model): with the
        model's guidance, whose root path is then imposed on the window made with the stronger
        `SWITCH_GUIDANCE` (`ROOT_FROM_FIRST_PASS`)."""
        s = self.settings
        window = s.window_for(self.model, self.controls.prompt)
        fields: dict[str, Any] = {"prompt": self.controls.prompt, "seconds": window / s.fps, "steps": s.steps,
                                  "seed": (s.seed + self._window_index) % 2**63, "guidance": self._guidance(),
                                  "postprocess": self.body.postprocess(bool(self.controls.targets)),
                                  "samples": 1}
        self._path_headings = None
        self._window_index += 1
        if context is None:  # the first window: steering and targets given before it start from standing
            start = WindowFrame((0.0, 0.0), 0.0, (0.0, 0.0), 0.0, 0.0, s.fps)
            controls = self.controls.window_constraints(start, 1, window)
            if controls:
                fields["constraints"] = controls
            return *self._run(fields), False
        controls = self.controls.window_constraints(frame, context.num_frames, window)
        fields["constraints"] = self.body.window_constraints(context, smooth, controls)
        fields["heading"] = frame.heading
        for c in controls:
            if c["type"] == "root2d":
                vectors = torch.tensor(c["global_root_heading"])
                self._path_headings = torch.atan2(vectors[:, 1], vectors[:, 0])
        if self._switch_windows <= 0:
            return *self._run(fields), False
        self._switch_windows -= 1
        first_pass = None
        if ROOT_FROM_FIRST_PASS and self._path_headings is None and hasattr(self.body, "root_path"):
            first_pass, first_timings = self._run(fields)
            path = self.body.root_path(first_pass, context.num_frames)
            fields["constraints"] = [*fields["constraints"], path]
        window, timings = self._run(fields | {"guidance": self._switch_guidance()})
        if first_pass is not None:
            timings = {k: float(timings.get(k, 0.0)) + float(first_timings.get(k, 0.0))
                       for k in set(timings) | set(first_timings)}
        return window, timings, first_pass is not None

    def _run(self, fields: dict) -> tuple[Motion, dict]:
        """The pipeline's one motion for a window's request ``fields``, and its timings."""
        if self.request is None:
            result = self.model.generate(**fields)
        else:
            result = self.model.generate(self.request.replace(timeline=None, **fields))
        return result.motions[0], result.report.timings

    def _guidance(self) -> tuple[float, float]:
        """Guidance weights of every window: the request's, else the model's own weights, given explicitly so
        that the human model runs them as separated guidance although its own default is regular CFG
        (docs/speed.md). A window's context keyframes are constraints, which separated guidance keeps out of
        the text branch, so the new prompt is pushed on its own; with regular guidance the context outweighs
        it (a bow after a walk, seed 0, leaned 2 degrees further than the walk, against 6 separated)."""
        if self.request is not None and self.request.guidance is not None:
            return self.request.guidance
        own = self.model.loaded.guidance
        return own.w_text, own.w_constr

    def _switch_guidance(self) -> tuple[float, float]:
        """Guidance of the window after a prompt switch: `SWITCH_GUIDANCE`, or the request's own with
        its text weight doubled."""
        given = None if self.request is None else self.request.guidance
        return SWITCH_GUIDANCE if given is None else (2.0 * given[0], given[1])

    def _log_window(self, first: int, new_frames: int, timings: dict, t0: float) -> None:
        wall = time.perf_counter() - t0
        sampling, post = float(timings.get("sampling", 0.0)), float(timings.get("postprocess", 0.0))
        self.windows.append(WindowStats(first, new_frames, sampling, post, max(0.0, wall - sampling - post)))
        done = time.perf_counter()
        for c in self.commands:
            if c.ready_wall is None and c.effective_frame < self._final_end():
                c.ready_wall = done


def open_stream(model, request=None, *, window_seconds: float | None = None,
                lookahead: float = LOOKAHEAD_SECONDS, steps: int | None = None,
                sized_by_prompt: bool = True) -> MotionStream:
    """A `MotionStream` of ``model`` (a loaded `MotionPipeline`); ``request`` (a `GenerationRequest`,
    optional) gives the first prompt, seed, heading, guidance and grounding, and for a model that
    needs one (the any-rig model) the rig; its ``seconds``, ``constraints`` and ``timeline`` are the
    stream's own. ``window_seconds``: default, each window as long as the model makes the current prompt
    at once (``model.window_for``: a run 2.35 s, a walk 5.9 s, a slow walk 7.5 s on the shipped human
    model; issue 57: in 3-s windows at 10 steps "walks at an easy pace" moved at 2.1-2.4 m/s, as fast as
    a jog, and 1.4-1.8 m/s in 5.9-s ones), else `WINDOW_SECONDS` or the model's window if shorter.
    ``sized_by_prompt=False``: windows of that default length whatever the prompt. The interactive faces (the
    app's live mode, the server's WebSocket stream) ask for it: a command is seen once the window made after
    it is, so a 5.9-s window doubles a command's wall-clock latency, and a bounded stream that makes 5.9 s at
    once can end before a client's next command arrives.
    ``steps``: DDIM steps per window (default `STREAM_STEPS`)."""
    if request is not None and not hasattr(request, "replace"):
        raise KinemaError(f"open_stream: request must be a GenerationRequest, got {type(request).__name__}")
    if request is not None and request.samples != 1:
        raise KinemaError(f"a stream makes one motion: request.samples must be 1, got {request.samples}")
    if getattr(model, "needs_rig", False):
        if request is None or request.rig is None:
            raise KinemaError("rig: the any-rig model streams on a rig: give the request's rig (a GLB/glTF or BVH "
                              "file or a training rig id)")
        rig = model.resolve_rig(request.rig)
        request = request.replace(rig=rig)
        body = RigBody(rig, float(model.fps))
    else:
        if request is not None and request.rig is not None:
            raise KinemaError("rig: a stream of this model moves its own skeleton; retarget the written stream "
                              "(kinema retarget) or stream an any-rig model (--model creatures) on the rig")
        body = HumanBody(model.skeleton)
    from_prompt = window_seconds is None and sized_by_prompt
    if window_seconds is None:
        window_seconds = min(WINDOW_SECONDS, float(model.window_seconds))
    seed = 0 if request is None else int(request.seed)
    settings = StreamSettings.checked(model, window_seconds, lookahead, steps, seed, from_prompt)
    return MotionStream(model, request, settings, body)
