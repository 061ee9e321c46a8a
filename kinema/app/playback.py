"""Playback: play/pause, a frame slider to scrub, loop, speed. A daemon thread advances the frame at
``fps * speed`` frames per second while playing; the slider is the single source of the shown frame
(assigning it redraws through its update callback)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

SPEEDS = {"0.25x": 0.25, "0.5x": 0.5, "1x": 1.0, "2x": 2.0}


def next_frame(frame: int, num_frames: int, *, loop: bool) -> tuple[int, bool]:
    """The frame after ``frame`` and whether playback goes on (it stops on the last frame unless looping)."""
    if frame + 1 < num_frames:
        return frame + 1, True
    return (0, True) if loop else (num_frames - 1, False)


#: the button that frames the character, clicked by the F key too (kinema.app.page_script)
FRAME_BUTTON = "Frame character"


class Player:
    """The playback panel and its clock; ``on_frame(frame)`` draws a frame."""

    def __init__(self, gui, fps: float, on_frame: Callable[[int], None]):
        self.fps, self.on_frame = fps, on_frame
        self.num_frames = 1
        self.segments: list[tuple[int, str]] = []  # (first frame, prompt) of each timeline segment shown
        with gui.add_folder("Playback"):
            self.play_btn = gui.add_button("Play", icon="player-play", hint="play / pause")
            self.slider = gui.add_slider(
                "Frame", min=0, max=1, step=1, initial_value=0, hint="scrub through the motion"
            )
            self.time_md = gui.add_markdown("")
            self.loop = gui.add_checkbox("Loop", True)
            self.speed = gui.add_dropdown("Speed", tuple(SPEEDS), initial_value="1x")
            self.follow = gui.add_checkbox(
                "Follow character", True, hint="the camera moves with the character while it plays or is scrubbed"
            )
            self.frame_btn = gui.add_button(FRAME_BUTTON, icon="focus-centered",
                                            hint="point the camera at the character (key F)")
        self.playing = False
        self._stop = threading.Event()
        self.play_btn.on_click(lambda _: self.set_playing(not self.playing))
        self.slider.on_update(lambda _: self._shown())
        self._thread = threading.Thread(target=self._run, name="kinema-app-playback", daemon=True)
        self._thread.start()

    @property
    def frame(self) -> int:
        return int(self.slider.value)

    def set_length(self, num_frames: int) -> None:
        """A new motion: the slider spans its frames; the shown frame is kept when it still exists."""
        self.num_frames = max(1, int(num_frames))
        self.slider.max = max(1, self.num_frames - 1)
        self.slider.disabled = self.num_frames < 2
        if self.frame >= self.num_frames:
            self.slider.value = 0
        self._shown()

    def seek(self, frame: int) -> None:
        self.slider.value = int(min(max(frame, 0), self.num_frames - 1))

    def set_playing(self, playing: bool) -> None:
        self.playing = bool(playing) and self.num_frames > 1
        self.play_btn.label = "Pause" if self.playing else "Play"
        self.play_btn.icon = "player-pause" if self.playing else "player-play"

    def set_segments(self, segments: list[tuple[int, str]]) -> None:
        """The timeline segments the shown motion is made of, (first frame, prompt) each ([]: none, an
        uploaded clip): the readout under the slider says which one plays and where it starts."""
        self.segments = list(segments)
        self._shown()

    def _shown(self) -> None:
        f = self.frame
        text = f"{f / self.fps:.2f} s / {(self.num_frames - 1) / self.fps:.2f} s (frame {f})"
        if len(self.segments) > 1:
            k = max(i for i, (start, _) in enumerate(self.segments) if start <= f or i == 0)
            start, prompt = self.segments[k]
            text += (f"  \nsegment {k + 1} of {len(self.segments)} from frame {start} ({start / self.fps:.2f} s): "
                     f"{prompt or '(no text)'}; starts at frames " + ", ".join(str(s) for s, _ in self.segments))
        self.time_md.content = text
        self.on_frame(f)

    def _run(self) -> None:
        last = time.perf_counter()
        while not self._stop.is_set():
            dt = 1.0 / (self.fps * SPEEDS.get(self.speed.value, 1.0))
            self._stop.wait(max(0.0, last + dt - time.perf_counter()))
            last = time.perf_counter()
            if self.playing:
                f, go_on = next_frame(self.frame, self.num_frames, loop=self.loop.value)
                self.slider.value = f
                if not go_on:
                    self.set_playing(False)

    def close(self) -> None:
        self._stop.set()
