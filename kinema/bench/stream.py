"""Stream benchmark (``kinema bench stream``): a long scripted live stream per thread count.

For each thread count the same stream runs: a cycle of commands every ``COMMAND_EVERY_SECONDS`` (walk,
steer right, stop steering and bow, wave, jog, steer left, walk, ...) for ``seconds`` of motion,
pulled half a second at a time. Measured: the real-time factor (seconds of motion per wall second,
and per CPU second of this process, which a busy shared machine disturbs less), each command's latency
(seconds of motion from the command to the first frame that obeys it, and wall seconds until that
frame was generated), the time per window split into sampling / post-processing / other, the resident
memory over the stream (the benchmark keeps no frame: kinema.stream.measure.JoinMeter keeps two
numbers a frame, so the memory is the stream's), the ground level per minute (drift), and pops at
every join of the whole stream (the largest pelvis speed change and joint acceleration near a join
against the largest away from joins).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import asdict, dataclass

import torch

from kinema.stream import MotionStream, StreamFrames, open_stream
from kinema.stream.measure import JoinMeter, rss_mb

#: seconds of motion between two commands of the benchmark's cycle
COMMAND_EVERY_SECONDS = 6.0
#: the cycle of commands: at each step, the stream methods called (name, arguments)
CYCLE = ((("set_prompt", ("A person walks forward.",)),),
         (("steer", (90.0, 1.2)),),
         (("clear", ()), ("set_prompt", ("A person bows.",))),
         (("set_prompt", ("A person waves with the right hand.",)),),
         (("set_prompt", ("A person jogs.",)),),
         (("steer", (-90.0, 2.5)),),
         (("clear", ()), ("set_prompt", ("A person walks forward.",))))
#: seconds of motion between two memory samples
MEMORY_EVERY_SECONDS = 30.0


@dataclass
class StreamBenchRow:
    threads: int
    seconds: float
    wall_s: float
    cpu_s: float
    realtime_wall: float
    realtime_cpu: float
    windows: int
    sampling_ms: float
    postprocess_ms: float
    other_ms: float
    latency_mean_s: float
    latency_max_s: float
    wall_latency_median_s: float
    wall_latency_max_s: float
    rss_first_mb: float
    rss_last_mb: float
    rss_max_mb: float
    ground_drift_cm: float
    joins_ok: bool
    join_acceleration: float
    inside_acceleration_max: float
    join_speed_change: float
    inside_speed_change_max: float

    def to_json(self) -> dict:
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in asdict(self).items()}


def _issue(stream: MotionStream, index: int) -> None:
    for name, args in CYCLE[index % len(CYCLE)]:
        getattr(stream, name)(*args)


def _ground(frames: StreamFrames) -> float:
    return float(torch.quantile(frames.positions[..., 1].amin(-1), 0.1))


def run_stream(model, seconds: float, threads: int, window_seconds: float, steps: int | None) -> StreamBenchRow:
    """One benchmark stream of ``seconds`` of motion on ``threads`` torch threads."""
    torch.set_num_threads(threads)
    stream = open_stream(model, window_seconds=window_seconds, steps=steps)
    fps, chunk = stream.fps, max(1, round(0.5 * stream.fps))
    total, every = round(seconds * fps), round(COMMAND_EVERY_SECONDS * fps)
    joins, grounds, memory, issued = JoinMeter(), {}, [], 0
    wall0, cpu0 = time.perf_counter(), time.process_time()
    while stream.frames_out < total:
        if stream.frames_out >= issued * every:
            _issue(stream, issued)
            issued += 1
        n = min(chunk, total - stream.frames_out, issued * every - stream.frames_out)
        frames = stream.next_frames(max(1, n))
        joins.feed(frames)
        minute = int(frames.start / fps // 60)
        grounds.setdefault(minute, []).append(_ground(frames))
        if frames.start % round(MEMORY_EVERY_SECONDS * fps) < frames.num_frames:
            memory.append(rss_mb())
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return _row(stream, threads, seconds, wall, cpu, joins, grounds, memory + [rss_mb()])


def _row(stream: MotionStream, threads: int, seconds: float, wall: float, cpu: float, meter: JoinMeter,
         grounds: dict, memory: list[float]) -> StreamBenchRow:
    windows = stream.windows[1:]  # the first window starts from nothing
    joins = meter.report(stream.seams())
    latencies = [c.latency_seconds for c in stream.commands]
    walls = [c.wall_seconds for c in stream.commands if c.wall_seconds is not None]
    per_minute = [statistics.median(v) for _, v in sorted(grounds.items())]

    def ms(name: str) -> float:
        return 1000 * statistics.mean(getattr(w, name) for w in windows)

    return StreamBenchRow(
        threads, seconds, wall, cpu, seconds / wall, seconds / cpu, len(stream.windows), ms("sampling"),
        ms("postprocess"), ms("other"), statistics.mean(latencies), max(latencies), statistics.median(walls),
        max(walls), memory[0], memory[-1], max(memory), 100 * (max(per_minute) - min(per_minute)), joins.ok,
        joins.join_acceleration, joins.inside_acceleration_max, joins.join_speed_change,
        joins.inside_speed_change_max)


def markdown(rows: list[StreamBenchRow]) -> str:
    """The rows as the table in docs/stream.md."""
    head = ("| threads | motion s | wall s | x real time (wall / CPU) | windows | ms per window: sampling / "
            "post / other | command latency, s of motion (mean / max) | wall latency s (median / max) | "
            "RSS MB (first / last / max) | ground drift cm | joins: pelvis speed change / windows' max m/s^2 | "
            "joins: accel / windows' max m/s^2 |")
    lines = [head, "|" + "---|" * 12]
    for r in rows:
        lines.append(
            f"| {r.threads} | {r.seconds:g} | {r.wall_s:.1f} | {r.realtime_wall:.1f} / {r.realtime_cpu:.1f} | "
            f"{r.windows} | {r.sampling_ms:.0f} / {r.postprocess_ms:.0f} / {r.other_ms:.0f} | "
            f"{r.latency_mean_s:.2f} / {r.latency_max_s:.2f} | {r.wall_latency_median_s:.2f} / "
            f"{r.wall_latency_max_s:.2f} | {r.rss_first_mb:.0f} / {r.rss_last_mb:.0f} / {r.rss_max_mb:.0f} | "
            f"{r.ground_drift_cm:.1f} | {r.join_speed_change:.1f} / {r.inside_speed_change_max:.1f} | "
            f"{r.join_acceleration:.0f} / {r.inside_acceleration_max:.0f}{'' if r.joins_ok else ' (pop)'} |")
    return "\n".join(lines)
