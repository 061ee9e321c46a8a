"""WebSocket ``/v1/stream``: a live `MotionStream` per connection (kinema.stream; docs/stream.md).

Protocol (JSON text messages). The client opens ``/v1/stream`` (with the API key in the
``Authorization: Bearer KEY`` or ``X-API-Key`` header when the server has keys) and sends first::

    {"type": "start", "prompt": "A person walks forward.", "model": "default", "seed": 0, "steps": 10,
     "window_seconds": 3, "lookahead": 0.15, "seconds": 60, "chunk_frames": 10, "realtime": true}

(every field but ``type`` optional; an any-rig model also needs ``"rig"``, one of its training rig
ids: the server reads no rig file a client names). The server answers ``{"type": "ready", "fps", "joints", "parents",
"offsets", "seconds"}`` (the skeleton: joint names, parent indices, bone offsets in metres) and then
sends ``{"type": "frames", "start", "fps", "root_translation", "local_rotations", "positions"}``
(quaternions w, x, y, z; metres), paced at the playback rate with ``REALTIME_AHEAD_SECONDS`` sent ahead
when ``realtime`` (else as fast as they are made). While it streams, the client sends
``{"type": "prompt", "text"}``, ``{"type": "steer", "direction_deg", "speed"}``, ``{"type": "target",
"joint", "position"}``, ``{"type": "clear"}`` or ``{"type": "stop"}``; each command is answered by
``{"type": "command", ...}`` (kinema.stream.CommandRecord: the frame it arrived at, the first frame that
obeys it, the latency in seconds of motion).

Bounds: ``seconds`` of motion per connection (at most `StreamLimits.max_seconds`; then ``{"type":
"end"}`` and close 1000), one stream per connection, at most `StreamLimits.max_streams` at once
(close 1013 "try again later" above it), messages of at most `StreamLimits.max_message_chars`, a
client that sends nothing for `StreamLimits.start_timeout_s` before ``start`` is closed. A bad message
or command closes the connection with code 1008 and a one-line reason; a client that goes away ends
its stream at the next chunk. ``KINEMA_STREAM_MAX_SECONDS`` and ``KINEMA_STREAM_MAX_STREAMS`` set the
limits of `kinema serve`.
"""

import asyncio
import hmac
import json
import logging
import math
import os
import reprlib
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from fastapi import FastAPI, WebSocket, WebSocketDisconnect

from kinema.errors import KinemaError
from kinema.finite import is_finite_real
from kinema.pipeline.request import GenerationRequest
from kinema.server.config import ServerConfig
from kinema.server.models import ModelRegistry
from kinema.stream import MotionStream, open_stream

#: seconds of frames sent ahead of real time when pacing (what a client buffers)
REALTIME_AHEAD_SECONDS = 0.5
START_KEYS = {"type", "prompt", "model", "seed", "steps", "window_seconds", "lookahead", "seconds",
              "chunk_frames", "realtime", "rig"}
COMMAND_KEYS = {"prompt": {"text"}, "steer": {"direction_deg", "speed"}, "target": {"joint", "position"},
                "clear": set(), "stop": set()}


@dataclass(frozen=True)
class StreamLimits:
    """Per-connection and per-server bounds of ``/v1/stream``."""

    max_seconds: float = 600.0
    max_streams: int = 2
    max_message_chars: int = 4096
    start_timeout_s: float = 10.0
    max_chunk_frames: int = 100

    @classmethod
    def from_env(cls) -> "StreamLimits":
        """The defaults, with ``KINEMA_STREAM_MAX_SECONDS`` / ``KINEMA_STREAM_MAX_STREAMS`` when set."""
        seconds = os.environ.get("KINEMA_STREAM_MAX_SECONDS")
        streams = os.environ.get("KINEMA_STREAM_MAX_STREAMS")
        try:
            limits = cls(max_seconds=float(seconds) if seconds else cls.max_seconds,
                         max_streams=int(streams) if streams else cls.max_streams)
        except ValueError:
            limits = None
        if limits is None or not (0 < limits.max_seconds < math.inf and limits.max_streams > 0):
            raise KinemaError("KINEMA_STREAM_MAX_SECONDS must be a positive number and KINEMA_STREAM_MAX_STREAMS "
                              "a positive integer")
        return limits


class StreamClosed(Exception):
    """End the connection with ``code`` and a one-line ``reason``."""

    def __init__(self, code: int, reason: str):
        super().__init__(reason)
        self.code = code
        self.reason = reason[:120]


class StreamSlots:
    """How many streams run now, bounded; thread-safe."""

    def __init__(self, limit: int):
        self.limit = limit
        self.active = 0
        self._lock = threading.Lock()

    def take(self) -> bool:
        with self._lock:
            if self.active >= self.limit:
                return False
            self.active += 1
            return True

    def give(self) -> None:
        with self._lock:
            self.active -= 1


def key_accepted(headers, keys: tuple[str, ...]) -> bool:
    """Whether the handshake carries one of ``keys`` (``Authorization: Bearer`` or ``X-API-Key``)."""
    if not keys:
        return True
    auth = headers.get("authorization", "")
    given = auth[7:].strip() if auth.lower().startswith("bearer ") else headers.get("x-api-key")
    return given is not None and sum(hmac.compare_digest(given.encode(), k.encode()) for k in keys) > 0


def add_stream_route(app: FastAPI, registry: ModelRegistry, config: ServerConfig,
                     limits: StreamLimits | None = None) -> None:
    """Serve ``/v1/stream`` on ``app`` (see the module docstring)."""
    limits = limits or StreamLimits.from_env()
    slots = StreamSlots(limits.max_streams)
    executor = ThreadPoolExecutor(max_workers=limits.max_streams, thread_name_prefix="kinema-stream")

    @app.websocket("/v1/stream")
    async def stream_socket(websocket: WebSocket):
        if not key_accepted(websocket.headers, config.api_keys):
            await websocket.close(code=1008, reason="missing or wrong API key")
            return
        await websocket.accept()
        if not slots.take():
            await websocket.close(code=1013, reason=f"all {limits.max_streams} stream slots are busy; try again later")
            return
        try:
            await _serve(websocket, registry, config, limits, executor)
        except StreamClosed as closed:
            await _close(websocket, closed.code, closed.reason)
        except (WebSocketDisconnect, OSError):
            pass  # the client went away (uvicorn raises an OSError subclass on a send after that)
        except Exception:  # a bug, not bad input: the client still gets a close frame that says so
            logging.getLogger("kinema.server").exception("stream failed")
            await _close(websocket, 1011, "internal error in the stream (the server log has the details)")
        finally:
            slots.give()


async def _close(websocket: WebSocket, code: int, reason: str) -> None:
    try:
        await websocket.close(code=code, reason=reason)
    except (RuntimeError, WebSocketDisconnect):
        pass  # the client went first


async def _receive_json(websocket: WebSocket, limits: StreamLimits, timeout: float | None = None) -> dict:
    """One JSON object from the client (close 1008 for anything else)."""
    try:
        text = await asyncio.wait_for(websocket.receive_text(), timeout)
    except TimeoutError:
        raise StreamClosed(1008, f"no 'start' message within {limits.start_timeout_s:g} s") from None
    except KeyError:  # a binary frame
        raise StreamClosed(1003, "send JSON text messages") from None
    if len(text) > limits.max_message_chars:
        raise StreamClosed(1009, f"message longer than {limits.max_message_chars} characters")
    try:
        message = json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        raise StreamClosed(1008, "not valid JSON") from None
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise StreamClosed(1008, "a message is a JSON object with a 'type'")
    return message


@dataclass
class StreamStart:
    """A checked ``start`` message."""

    stream: MotionStream
    seconds: float
    chunk_frames: int
    realtime: bool


def _number(message: dict, key: str, default, low: float, high: float, kind=float):
    value = message.get(key, default)
    if value is None:
        return None
    if not is_finite_real(value) or not low <= value <= high or (kind is int and value != int(value)):
        raise StreamClosed(1008, f"start: '{key}' must be a{'n integer' if kind is int else ' number'} in "
                                 f"[{low:g}, {high:g}], got {reprlib.repr(value)}")
    return kind(value)


def _start(message: dict, registry: ModelRegistry, config: ServerConfig, limits: StreamLimits) -> StreamStart:
    """The stream a ``start`` message asks for (close 1008 naming what is wrong)."""
    unknown = sorted(set(message) - START_KEYS)
    if message["type"] != "start" or unknown:
        raise StreamClosed(1008, f"the first message is {{'type': 'start', ...}}; unknown keys {unknown}"
                           if unknown else "the first message must be {'type': 'start', ...}")
    name = message.get("model")
    served = registry.models.get(name) if name is not None else next(iter(registry.models.values()))
    if served is None:
        raise StreamClosed(1008, f"unknown model {name!r}; this server has {registry.names}")
    prompt = message.get("prompt", "")
    if not isinstance(prompt, str) or len(prompt) > config.limits.max_prompt_chars:
        raise StreamClosed(1008, f"start: 'prompt' must be a string of at most {config.limits.max_prompt_chars} chars")
    steps = _number(message, "steps", None, 1, served.max_steps(config.limits.max_steps), int)
    rig = _rig(message, served.model)
    try:
        request = GenerationRequest(prompt=prompt, seed=_number(message, "seed", 0, 0, 2**63 - 1, int), rig=rig)
        stream = open_stream(served.model, request, window_seconds=_number(message, "window_seconds", None, 0, 60),
                             lookahead=_number(message, "lookahead", 0.15, 0, 10), steps=steps,
                             sized_by_prompt=False)
    except KinemaError as err:
        raise StreamClosed(1008, f"start: {err}") from None
    seconds = _number(message, "seconds", limits.max_seconds, 0, limits.max_seconds)
    chunk = _number(message, "chunk_frames", 10, 1, limits.max_chunk_frames, int)
    realtime = message.get("realtime", True)
    if not isinstance(realtime, bool):
        raise StreamClosed(1008, "start: 'realtime' must be true or false")
    return StreamStart(stream, seconds, chunk, realtime)


def _rig(message: dict, model) -> str | None:
    """The ``rig`` of a start message: one of an any-rig model's training rigs, by id (a server reads no
    rig files a client names); None for a model with a skeleton of its own."""
    rig = message.get("rig")
    if not getattr(model, "needs_rig", False):
        if rig is not None:
            raise StreamClosed(1008, "start: 'rig' is for an any-rig model; this model moves its own skeleton")
        return None
    known = [r.name for r in model.rigs()]
    if not isinstance(rig, str) or rig not in known:
        raise StreamClosed(1008, f"start: 'rig' must be one of the model's training rigs "
                                 f"({', '.join(known[:6])}{', ...' if len(known) > 6 else ''}), got {rig!r}")
    return rig


def _check_command(message: dict) -> dict:
    kind = message["type"]
    allowed = COMMAND_KEYS.get(kind)
    if allowed is None:
        raise StreamClosed(1008, f"unknown message type {kind!r}; expected one of {sorted(COMMAND_KEYS)}")
    extra = sorted(set(message) - allowed - {"type"})
    if extra:
        raise StreamClosed(1008, f"{kind}: unknown keys {extra}; expected {sorted(allowed)}")
    return message


def _apply(stream: MotionStream, message: dict) -> dict:
    """Issue one command on the stream (between chunks); its record as JSON."""
    kind = message["type"]
    try:
        if kind == "prompt":
            record = stream.set_prompt(message.get("text", ""))
        elif kind == "steer":
            record = stream.steer(message.get("direction_deg"), message.get("speed", 1.2))
        elif kind == "target":
            record = stream.target(message.get("joint"), message.get("position"))
        else:
            record = stream.clear()
    except KinemaError as err:
        raise StreamClosed(1008, str(err).splitlines()[0]) from None
    return {"type": "command"} | record.to_json()


async def _serve(websocket: WebSocket, registry: ModelRegistry, config: ServerConfig, limits: StreamLimits,
                 executor: ThreadPoolExecutor) -> None:
    """One connection: the start message, then frames out and commands in until done or gone."""
    start = _start(await _receive_json(websocket, limits, limits.start_timeout_s), registry, config, limits)
    skel = start.stream.skeleton
    await websocket.send_json({"type": "ready", "fps": start.stream.fps, "joints": list(skel.names),
                               "parents": [int(p) for p in skel.parents], "offsets": skel.offsets.tolist(),
                               "seconds": start.seconds})
    inbox: asyncio.Queue = asyncio.Queue()
    reader = asyncio.create_task(_read_commands(websocket, limits, inbox))
    try:
        await _produce(websocket, start, inbox, executor)
    finally:
        reader.cancel()


async def _read_commands(websocket: WebSocket, limits: StreamLimits, inbox: asyncio.Queue) -> None:
    """Queue the client's commands; a bad one (or the client leaving) is queued as the exception."""
    try:
        while True:
            await inbox.put(_check_command(await _receive_json(websocket, limits)))
    except (StreamClosed, WebSocketDisconnect) as err:
        await inbox.put(err)


async def _produce(websocket: WebSocket, start: StreamStart, inbox: asyncio.Queue,
                   executor: ThreadPoolExecutor) -> None:
    """Frames out, paced, with queued commands applied between chunks."""
    stream, loop = start.stream, asyncio.get_running_loop()
    total = max(1, round(start.seconds * stream.fps))
    began = time.monotonic()
    while stream.frames_out < total:
        while not inbox.empty():
            message = inbox.get_nowait()
            if isinstance(message, Exception):
                raise message
            if message["type"] == "stop":
                total = stream.frames_out
                break
            await websocket.send_json(_apply(stream, message))
        if stream.frames_out >= total:
            break
        n = min(start.chunk_frames, total - stream.frames_out)
        frames = await loop.run_in_executor(executor, stream.next_frames, n)
        await websocket.send_json({"type": "frames"} | frames.to_json())
        if start.realtime:
            due = began + stream.frames_out / stream.fps - REALTIME_AHEAD_SECONDS
            await asyncio.sleep(max(0.0, due - time.monotonic()))
        else:
            await asyncio.sleep(0)
    await websocket.send_json({"type": "end", "frames": stream.frames_out})
    raise StreamClosed(1000, "stream finished")
