"""Long prompts as continuation: a prompt longer than its action was captured at is made window by window.

Why (issue 57): the human model learned each action at the length of its captures, and makes it for that
long, whatever the length asked. Measured on the shipped model, one 10-s window, raw, seeds 0-2, pelvis
ground speed per second: "A man runs straight ahead." (run captures: median 3.15 s) runs at 2.1-3.8 m/s
for 3 s, then 0.15-1.4 m/s, in place, to the end; "A person walks ahead." (walk captures: 7.85 s) walks
at 1.0-1.6 m/s for 7 s, then 0.4-0.9 m/s at 7-9 s. So a prompt is sampled in one window only up to
`CAPTURE_SHARE` of its captures' length (the median length of the training clips of the caption it is
grounded on, or its nearest caption: ``KnownPrompts.caption_seconds``) and of the model's window; a
longer one is a stream (kinema.stream: the same prompt, each window continuing the last frames generated,
imposed as keyframes) of windows that long, then post-processed as one motion. A 10-s run is then six
2.35-s windows that each keep running. After the first window the stream is steered straight on (a root
path every later window follows, kinema.stream.controls.Steer): left alone, each window picked its own
speed and two walks of six (held-out phrasings, seeds 0-2, 10 s; scripts/long_motion_probe.py) slowed to
0.67-0.71 x their first seconds; steered, all six keep 0.95-0.99 x and the runs 1.00-1.03 x. The speed
steered at is the one the captures of the prompt's caption travel at (`captured_speed`: the median steady
speed of its training clips, ``KnownPrompts.caption_speeds``, kinema.data.phases), else the speed the
first window settled at (`cruising_speed`): the model's own windows travel 1.3-1.45 x faster than the
captures of their caption (held-out phrasings grounded on slow walks: 0.93-1.33 m/s for captures at
0.78 m/s; on gentle runs 2.2-2.3 for 1.67; on runs 3.2-3.8 for 2.7-2.8), so a stroll kept at the first
window's speed was no slower than 1.1 m/s.

Only prompts whose actions are all travel (`CONTINUED_ACTIONS`: walks and runs, "A person walks forward
happily.", not "walks and turns left" nor "bows") are continued: another action is made once, in one
window of up to 10 s, as before. Only requests that are a single prompt without constraints, objectives or
keyjoint planning are continued. A timeline's segment longer than its `learned_window` is made of equal
pieces of the same prompt no longer than it, joined like any two segments (transition windows,
kinema.human.segments), so a 10-s run after a walk runs for 10 s as well.
Sample ``i`` of a continued request is the stream of seed ``seed + i``.
"""

from __future__ import annotations

import time
from dataclasses import replace

from kinema.human.targets import run_postprocess
from kinema.model.actions import actions_in
from kinema.motion.contacts import foot_contacts
from kinema.motion.core import Motion
from kinema.pipeline.request import GenerationRequest
from kinema.pipeline.result import GenerationReport, GenerationResult
from kinema.stream import open_stream
from kinema.stream.controls import MAX_SPEED
from kinema.stream.measure import frames_to_motion

#: share of an action's capture length (and of the model's window) that one window holds
CAPTURE_SHARE = 0.75
#: the shortest window (s): a few captions are carried only by a short clip (a 0.65-s dash)
MIN_WINDOW_SECONDS = 2.0
#: seconds of the first window after which its speed is measured (its first second starts from standing)
SETTLE_SECONDS = 1.0
#: the actions (kinema.model.actions) a prompt may name to be continued: travel goes on for as long as asked,
#: while a bow, a kick or a turn made again in every window would be made several times
CONTINUED_ACTIONS = frozenset({"walk", "run"})


def continuation_window(pipeline, request: GenerationRequest, seconds: float) -> float | None:
    """The window (s) a request of ``seconds`` is continued in, or None when it is made in one go: it is
    not a lone unconstrained prompt, the model knows no capture lengths, or the prompt's action lasts."""
    r = request
    if (r.timeline is not None or not r.prompt.strip() or r.constraints is not None or r.objectives is not None
            or r.keyjoint_model not in (None, "none")):
        return None
    window = learned_window(pipeline, r.prompt, r.grounding_settings())
    # a window's own request (window frames / fps seconds) is never continued again
    return window if window is not None and seconds > window + 0.5 / float(pipeline.fps) else None


def learned_window(pipeline, prompt: str, grounding=None) -> float | None:
    """The longest stretch (s, whole frames) ``prompt`` is made in at once: `CAPTURE_SHARE` of its captures'
    length and of the model's window, at least `MIN_WINDOW_SECONDS`; None for a prompt that is not only
    travel (`CONTINUED_ACTIONS`) or without known capture lengths."""
    actions = actions_in(prompt)
    if not actions or not actions <= CONTINUED_ACTIONS:
        return None
    captured = captured_seconds(pipeline, prompt, grounding)
    if captured is None:
        return None
    fps = float(pipeline.fps)
    return round(max(MIN_WINDOW_SECONDS, CAPTURE_SHARE * min(captured, float(pipeline.window_seconds))) * fps) / fps


def captured_seconds(pipeline, prompt: str, grounding=None) -> float | None:
    """How long the captures of ``prompt`` last (:func:`captured_caption`'s clips); None without known
    capture lengths or for an empty prompt."""
    caption = captured_caption(pipeline, prompt, grounding)
    return None if caption is None else pipeline.known_prompts.seconds_of(caption)


def captured_speed(pipeline, prompt: str, grounding=None) -> float | None:
    """How fast the captures of ``prompt`` travel (m/s, the median steady speed of :func:`captured_caption`'s
    clips); None without known capture speeds, for an empty prompt or a caption whose clips do not travel
    or have no steady second (a 0.65-s dash)."""
    caption = captured_caption(pipeline, prompt, grounding)
    return None if caption is None else pipeline.known_prompts.speed_of(caption)


def captured_caption(pipeline, prompt: str, grounding=None) -> str | None:
    """The training caption whose captures stand for ``prompt``: the caption it is grounded on (the first of
    the blend), else itself when it is one, else its nearest caption; None without known prompts or for an
    empty prompt."""
    known = pipeline.known_prompts
    if known is None or not prompt.strip():
        return None
    grounded = pipeline.ground_prompts([prompt], grounding)[prompt]
    if grounded.captions:
        return grounded.captions[0][0]
    if prompt.strip() in known.caption_set:
        return prompt.strip()
    return pipeline.match_prompts([prompt])[0].nearest[0][0]


def cruising_speed(motion: Motion) -> float:
    """Ground speed (m/s, straight line) of a window from `SETTLE_SECONDS` (or its middle) to its end: the
    speed its prompt was made at, after the start every window of the model makes from standing."""
    settle = min(round(SETTLE_SECONDS * motion.fps), motion.num_frames // 2)
    xz = motion.root_translation[:, [0, 2]].double()
    return float((xz[-1] - xz[settle]).norm()) * motion.fps / max(motion.num_frames - 1 - settle, 1)


def continued(pipeline, request: GenerationRequest, seconds: float, window: float, steps: int) -> GenerationResult:
    """``request.samples`` motions of ``seconds`` each, made as streams of ``window``-second windows with
    ``steps`` DDIM steps, post-processed whole when the request asks; the report of the call."""
    t0 = time.perf_counter()
    frames = round(seconds * pipeline.fps)
    window_request = request.replace(rig=None, robot=None, robot_mapping=None, fps=None, format=None,
                                     seconds=None, samples=1)
    motions, residuals, post_seconds, windows = [], [], 0.0, 0
    speed = captured_speed(pipeline, request.prompt, request.grounding_settings())  # None: the first window's
    for i in range(request.samples):
        stream = open_stream(pipeline, window_request.replace(seed=(request.seed + i) % 2**63),
                             window_seconds=window, lookahead=0.0, steps=steps)
        if speed is not None:  # every window at the captures' speed, the first from standing
            stream.steer(None, min(MAX_SPEED, speed))
        parts = [stream.next_frames(1)]
        parts.append(stream.next_frames(stream.buffered_frames))  # the rest of window 1
        if speed is None:  # straight on at the speed the first window settled at
            stream.steer(None, min(MAX_SPEED, cruising_speed(frames_to_motion(parts, pipeline.skeleton))))
        parts.append(stream.next_frames(frames - sum(p.num_frames for p in parts)))
        motion = frames_to_motion(parts, pipeline.skeleton)
        windows += len(stream.windows)
        # the stream's frames carry no predicted contacts: label them as the training data's are labelled
        motion = replace(motion, foot_contacts=foot_contacts(motion.positions, motion.fps, motion.skeleton))
        t_post = time.perf_counter()
        report: dict = {}
        if request.postprocess:
            motion, report = run_postprocess(motion, None, pipeline.representation)
        post_seconds += time.perf_counter() - t_post
        motions.append(motion)
        residuals.append(report)
    matches = pipeline.match_prompts([request.prompt], request.grounding_settings())
    texts = pipeline.ground_prompts([request.prompt], request.grounding_settings())
    own = pipeline.loaded.guidance  # the stream's windows run separated guidance (kinema.stream.continuation)
    guidance = request.guidance if request.guidance is not None else (own.w_text, own.w_constr)
    t1 = time.perf_counter()
    result_report = GenerationReport(
        seconds=t1 - t0, segments=1, frames=frames, steps=steps, guidance=guidance, guidance_mode="separated",
        seed=request.seed, residuals=residuals,
        warnings=[m.warning() for m in matches if not m.known] + [w for r in residuals for w in r.get("warnings", [])],
        prompts=[pipeline.prompt_report(m, {}, texts) | {"continued": {
                     "window_seconds": round(window, 3), "windows": windows // request.samples,
                     "speed": None if speed is None else round(speed, 3),
                     "speed_from": "first window" if speed is None else "captures"}}
                 for m in matches],
        timings={"sampling": t1 - t0 - post_seconds, "postprocess": post_seconds}, joints=pipeline.skeleton.num_joints,
    )
    return GenerationResult(motions, result_report)
