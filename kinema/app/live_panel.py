"""Live mode: the character moves continuously (a kinema.stream `MotionStream`) while the user switches
its prompt, steers it, and reads how long each command took to show.

The "Live" folder holds Start / Stop, a prompt box with **Switch prompt** (Enter in the box does the
same), four steer buttons and a readout. Steering is a heading and a speed: **Turn left** / **Turn
right** turn the heading by `TURN_DEG`, **Faster** / **Slower** step through `SPEEDS` (0: no steering,
the prompt alone decides where the character goes). The readout gives the last command's latency:
seconds of motion until the first frame that obeys it, and wall seconds from the click until that
frame was drawn, and the stream's real-time factor.

Keys: viser (1.1) sends no key events to Python, and its own client moves the camera with WASD and
the arrow keys. While live mode runs, the page script (kinema.app.page_script) catches those keys
first and clicks the matching steer button (`BUTTONS`): up / W faster, down / S slower, left / A and
right / D turn. They move the camera again once live mode stops, and never while a text box has focus.

Threads: one makes frames (it owns the stream and applies queued commands between ``next_frames``
calls: a stream is not thread-safe) and keeps `AHEAD_SECONDS` drawn ahead; one draws them at the
model's frame rate. Positions are world metres, Y up; headings in degrees, 0 = +Z, 90 = +X.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from kinema.app.camera import CameraFollow
from kinema.app.views import SELECTED_COLOR, SkeletonView
from kinema.errors import KinemaError
from kinema.pipeline.request import GenerationRequest
from kinema.stream import open_stream
from kinema.stream.measure import frames_to_motion

#: steered speeds Faster / Slower step through, m/s (0: no steering)
SPEEDS = (0.0, 0.8, 1.4, 2.5, 4.0)
#: degrees one Turn left / Turn right turns the steered heading
TURN_DEG = 30.0
#: seconds of frames made ahead of the one drawn (what a command has to wait behind, besides the
#: stream's own lookahead)
AHEAD_SECONDS = 0.3
#: frames made per ``next_frames`` call
CHUNK_FRAMES = 3
#: seconds between two readout updates
READOUT_EVERY = 0.25
#: the first prompt of live mode, per kind of model
HUMAN_PROMPT = "A person walks forward."
RIG_PROMPT = "An animal walks."

BUTTONS = {"faster": "Faster", "slower": "Slower", "left": "Turn left", "right": "Turn right"}
START, STOP, SWITCH = "Start live", "Stop live", "Switch prompt"

@dataclass
class Steering:
    """The live heading (degrees; None: not steered yet, the character's facing is taken) and the
    index into `SPEEDS`."""

    heading: float | None = None
    speed_index: int = 0

    @property
    def speed(self) -> float:
        return SPEEDS[self.speed_index]

    def press(self, button: str, facing_deg: float) -> tuple[float, float] | None:
        """The new (heading, speed) after ``button`` (`BUTTONS` key), or None: stop steering."""
        if self.heading is None or self.speed_index == 0:
            self.heading = facing_deg
        if button == "faster":
            self.speed_index = min(len(SPEEDS) - 1, self.speed_index + 1)
        elif button == "slower":
            self.speed_index = max(0, self.speed_index - 1)
        else:
            self.heading += TURN_DEG if button == "left" else -TURN_DEG  # left of a figure facing +Z is +X
            self.heading = (self.heading + 180.0) % 360.0 - 180.0
            self.speed_index = max(1, self.speed_index)
        return None if self.speed_index == 0 else (self.heading, self.speed)


@dataclass
class Shown:
    """A command waiting to be seen: its stream record and when it was clicked (``time.perf_counter``)."""

    record: object
    clicked: float


class LiveRun:
    """One live stream drawn in a tab (see the module docstring); ``stop()`` ends both threads."""

    def __init__(self, session, prompt: str):
        self.session = session
        model = session.model
        rig = session.rig.skeleton if getattr(model, "needs_rig", False) else None
        self.stream = open_stream(model, GenerationRequest(prompt=prompt, seed=int(session.seed.value), rig=rig),
                                  sized_by_prompt=False)  # interactive: short windows, short command latency
        self.fps = self.stream.fps
        self.view = SkeletonView(session.client.scene, "/live", self.stream.skeleton, color=SELECTED_COLOR,
                                 contacts=[])
        self.camera = CameraFollow(session.client, lambda: bool(session.player.follow.value))
        self.commands: queue.Queue = queue.Queue()
        self.ready: deque = deque()  # (stream frame, positions (J, 3)) made, not drawn yet
        self.waiting: list[Shown] = []
        self.latencies: list[tuple[float, float]] = []  # (seconds of motion, wall seconds to the screen)
        self.last = None  # the last StreamFrames made
        self.drawn = -1
        self.stalls = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._made = threading.Thread(target=self._make, name="kinema-live-make", daemon=True)
        self._draw = threading.Thread(target=self._show, name="kinema-live-draw", daemon=True)
        self._made.start()
        self._draw.start()

    # ------------------------------------------------------------------ commands (any thread)
    def send(self, kind: str, *args) -> None:
        """Queue a stream command (``set_prompt``, ``steer``, ``clear``) for the making thread."""
        self.commands.put((kind, args, time.perf_counter()))

    def facing_deg(self) -> float:
        """The facing of the last frame made, degrees (0 before any)."""
        last = self.last
        if last is None:
            return 0.0
        motion = frames_to_motion([last], self.stream.skeleton).crop(last.num_frames - 1)
        return float(np.degrees(float(self.stream.body.facing(motion)[0])))

    # ------------------------------------------------------------------ threads
    def _make(self) -> None:
        ahead = max(1, round(AHEAD_SECONDS * self.fps))
        try:
            while not self._stop.is_set():
                self._apply_commands()
                if len(self.ready) >= ahead:
                    self._stop.wait(0.01)
                    continue
                frames = self.stream.next_frames(CHUNK_FRAMES)
                self.last = frames
                positions = frames.positions.detach().double().numpy()
                with self._lock:
                    self.ready.extend((frames.start + i, positions[i]) for i in range(frames.num_frames))
        except KinemaError as err:
            self.error = str(err).splitlines()[0]
        except Exception as err:  # noqa: BLE001 - the tab says what stopped the stream instead of a silent thread
            self.error = f"{type(err).__name__}: {err}"
        finally:
            self._stop.set()

    def _apply_commands(self) -> None:
        while True:
            try:
                kind, args, clicked = self.commands.get_nowait()
            except queue.Empty:
                return
            record = getattr(self.stream, kind)(*args)  # frames already made stay: they were handed out
            with self._lock:
                self.waiting.append(Shown(record, clicked))

    def _show(self) -> None:
        dt, due, said = 1.0 / self.fps, time.perf_counter(), 0.0
        while not self._stop.is_set():
            self._stop.wait(max(0.0, due - time.perf_counter()))
            due = max(due + dt, time.perf_counter() - dt)
            with self._lock:
                item = self.ready.popleft() if self.ready else None
            if item is None:
                if self.drawn >= 0:
                    self.stalls += 1
                continue
            frame, positions = item
            with self._lock:
                if self._stop.is_set():
                    return
                self.view.positions = positions[None]
                self.view.show(0)
            self.drawn = frame
            if frame == 0:
                self.camera.frame(positions, positions[0])  # the first frame: framed from the default angle
            self.camera.follow(positions[0])
            self.session.ground_under(positions[0])
            self._seen(frame)
            if time.perf_counter() - said > READOUT_EVERY:
                said = time.perf_counter()
                self.session.live.readout(self)

    def _seen(self, frame: int) -> None:
        now = time.perf_counter()
        with self._lock:
            seen = [w for w in self.waiting if frame >= w.record.effective_frame]
            self.waiting = [w for w in self.waiting if frame < w.record.effective_frame]
        for w in seen:
            self.latencies.append((w.record.latency_seconds, now - w.clicked))

    def realtime_factor(self) -> float | None:
        """Seconds of motion made per wall second spent making it (windows after the first)."""
        windows = self.stream.windows[1:]
        wall = sum(w.wall for w in windows)
        return None if not windows or wall <= 0 else sum(w.new_frames for w in windows) / self.fps / wall

    def stop(self) -> None:
        self._stop.set()
        if threading.current_thread() is not self._draw:
            self._draw.join(timeout=2.0)
        with self._lock:
            self.view.remove()


class LivePanel:
    """The "Live" folder of a tab (see the module docstring)."""

    def __init__(self, gui, session):
        self.session = session
        self.run: LiveRun | None = None
        self.steering = Steering()
        prompt = RIG_PROMPT if getattr(session.model, "needs_rig", False) else HUMAN_PROMPT
        with gui.add_folder("Live", expand_by_default=False):
            self.start_btn = gui.add_button(START, icon="player-play", color="green",
                                            hint="the character moves on and on; steer it and switch its prompt")
            self.stop_btn = gui.add_button(STOP, icon="player-stop", color="red", visible=False)
            self.prompt = gui.add_text("Live prompt", prompt, hint="what the character does; Enter switches")
            self.switch_btn = gui.add_button(SWITCH, icon="arrows-exchange", disabled=True)
            self.steer_btns = {
                key: gui.add_button(label, icon=icon, disabled=True)
                for key, label, icon in (("faster", BUTTONS["faster"], "arrow-up"),
                                         ("left", BUTTONS["left"], "arrow-left"),
                                         ("right", BUTTONS["right"], "arrow-right"),
                                         ("slower", BUTTONS["slower"], "arrow-down"))
            }
            self.status = gui.add_markdown("Press **Start live**: arrow keys or WASD steer, the prompt box "
                                           "switches what it does.")
        self.start_btn.on_click(lambda _: self.start())
        self.stop_btn.on_click(lambda _: self.stop())
        self.switch_btn.on_click(lambda _: self.switch())
        for key, btn in self.steer_btns.items():
            btn.on_click(lambda _, key=key: self.steer(key))

    @property
    def running(self) -> bool:
        return self.run is not None

    def start(self) -> None:
        s = self.session
        if self.run is not None:
            return
        if s.job is not None:
            s.notify("Busy", "wait for the generation to finish before going live", error=True)
            return
        s.player.set_playing(False)
        try:
            self.run = LiveRun(s, self.prompt.value)
        except KinemaError as err:
            s.notify("Cannot go live", str(err).splitlines()[0], error=True)
            return
        self.steering = Steering()
        with s.lock:
            for group in s.views:
                for view in group:
                    view.remove()
        self._buttons(live=True)
        self.status.content = "Live: starting..."

    def stop(self) -> None:
        run, self.run = self.run, None
        if run is None:
            return
        run.stop()
        self.session.ground.position = (0.0, 0.0, 0.0)
        self._buttons(live=False)
        self.status.content = self._summary(run, "Stopped.")
        self.session.select_sample(self.session.selected)  # the timeline's motion again

    def switch(self) -> None:
        if self.run is not None:
            self.run.send("set_prompt", self.prompt.value)

    def steer(self, key: str) -> None:
        run = self.run
        if run is None:
            return
        wanted = self.steering.press(key, run.facing_deg())
        if wanted is None:
            run.send("clear")
        else:
            run.send("steer", *wanted)

    def readout(self, run: LiveRun) -> None:
        """Called by the drawing thread: the latency readout (and the error that stopped the stream)."""
        if run is not self.run:
            return
        if run.error is not None:
            self.session.notify("Live mode stopped", run.error, error=True)
            self.stop()
            return
        st = self.steering
        steer = "not steered" if st.speed_index == 0 else f"heading {st.heading:.0f} deg at {st.speed:g} m/s"
        self.status.content = self._summary(run, f"Live, {run.drawn / run.fps:.1f} s; {steer}.")

    @staticmethod
    def _summary(run: LiveRun, head: str) -> str:
        lines = [head]
        if run.latencies:
            motion, wall = run.latencies[-1]
            lines.append(f"Last command: {motion:.2f} s of motion, {wall:.2f} s from click to screen.")
        rtf = run.realtime_factor()
        if rtf is not None:
            lines.append(f"Made at {rtf:.1f}x real time; {run.stalls} frame(s) waited for.")
        return "  \n".join(lines)

    def _buttons(self, *, live: bool) -> None:
        self.start_btn.visible, self.stop_btn.visible = not live, live
        self.switch_btn.disabled = not live
        for btn in self.steer_btns.values():
            btn.disabled = not live
        self.session.gen_btn.disabled = live

    def close(self) -> None:
        if self.run is not None:
            self.run.stop()
            self.run = None
