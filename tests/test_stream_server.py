"""WebSocket ``/v1/stream`` (kinema/server/stream.py) through a real uvicorn `kinema serve` on 127.0.0.1.

One server for the module: the shipped model, an API key, at most 4 s of motion per connection and one
stream at a time (KINEMA_STREAM_MAX_SECONDS / KINEMA_STREAM_MAX_STREAMS). Checks: frames out and
commands in with their latency, the end of a bounded stream (close 1000), one-line close reasons for
bad input (1008), the concurrent-stream limit (1013) and that a client leaving frees its slot.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time

import pytest
from server_process import free_port, stop_server

websockets = pytest.importorskip("websockets")
pytest.importorskip("uvicorn")
from websockets.exceptions import ConnectionClosed, InvalidStatus  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

KEY = "stream-test-key-0123456789abcdef"
AUTH = {"Authorization": f"Bearer {KEY}"}



@pytest.fixture(scope="module")
def url(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("stream_server")
    (tmp / "keys").write_text(f"{KEY}\n")
    port = free_port()
    env = os.environ | {"OMP_NUM_THREADS": "1", "KINEMA_STREAM_MAX_SECONDS": "4", "KINEMA_STREAM_MAX_STREAMS": "1"}
    log = (tmp / "server.log").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "kinema", "serve", "--port", str(port), "--api-key-file",
                             str(tmp / "keys"), "--threads", "1", "--log-level", "warning"],
                            stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=env)
    try:
        deadline = time.monotonic() + 120
        while True:
            assert proc.poll() is None, (tmp / "server.log").read_text()
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "server did not start in 120 s"
                time.sleep(0.2)
        yield f"ws://127.0.0.1:{port}/v1/stream"
    finally:
        stop_server(proc)
        log.close()
        text = (tmp / "server.log").read_text()
        assert "Traceback" not in text, text


def _start(ws, **fields) -> dict:
    ws.send(json.dumps({"type": "start", "prompt": "A person walks forward."} | fields))
    return json.loads(ws.recv(timeout=60))


def _closed(ws) -> ConnectionClosed:
    """Read until the server closes; the close exception."""
    try:
        while True:
            ws.recv(timeout=60)
    except ConnectionClosed as closed:
        return closed


def test_frames_out_commands_in_until_the_bound(url) -> None:
    with connect(url, additional_headers=AUTH) as ws:
        ready = _start(ws, realtime=False, chunk_frames=10)
        assert ready["type"] == "ready" and ready["fps"] == 20 and len(ready["joints"]) == 21
        assert ready["seconds"] == 4 and len(ready["offsets"]) == 21
        frames, commands, ended = [], [], None
        while ended is None:
            data = json.loads(ws.recv(timeout=60))
            if data["type"] == "frames":
                assert data["start"] == len(frames)
                frames += data["positions"]
                if len(frames) == 20:
                    ws.send(json.dumps({"type": "prompt", "text": "A person bows."}))
                    ws.send(json.dumps({"type": "steer", "direction_deg": 45, "speed": 1.0}))
            elif data["type"] == "command":
                commands.append(data)
            else:
                ended = data
        assert ended == {"type": "end", "frames": 80} and len(frames) == 80
        assert [c["kind"] for c in commands] == ["prompt", "steer"]
        assert all(c["latency_seconds"] <= 0.5 for c in commands)
        assert len(frames[0]) == 21 and len(frames[0][0]) == 3
        closed = _closed(ws)
        assert closed.rcvd.code == 1000


@pytest.mark.parametrize(("first", "then", "reason"), [
    ({"type": "start", "seconds": 60}, None, "'seconds' must be"),
    ({"type": "start", "colour": "red"}, None, "unknown keys ['colour']"),
    ({"type": "prompt", "text": "x"}, None, "first message"),
    ({"type": "start", "realtime": False}, {"type": "steer", "direction_deg": 0, "speed": 50}, "speed"),
    ({"type": "start", "realtime": False}, {"type": "jump"}, "unknown message type 'jump'"),
    ({"type": "start", "realtime": False}, "not json", "not valid JSON"),
    # issue 61: numbers too large for a float were an OverflowError and a drop without a close frame
    ({"type": "start", "seed": 10**400}, None, "'seed' must be an integer"),
    ({"type": "start", "realtime": False}, {"type": "steer", "speed": 10**400}, "speed must be a finite number"),
    ({"type": "start", "realtime": False}, {"type": "target", "joint": "right_hand", "position": [10**400, 0, 0]},
     "position must be three numbers"),
])
def test_bad_input_closes_with_a_reason(url, first, then, reason) -> None:
    with connect(url, additional_headers=AUTH) as ws:
        ws.send(json.dumps(first))
        if then is not None:
            assert json.loads(ws.recv(timeout=60))["type"] == "ready"
            ws.send(then if isinstance(then, str) else json.dumps(then))
        closed = _closed(ws)
        assert closed.rcvd.code == 1008 and reason in closed.rcvd.reason, closed.rcvd


def test_a_wrong_key_is_refused(url) -> None:
    with pytest.raises(InvalidStatus):
        with connect(url, additional_headers={"Authorization": "Bearer wrong-key-0123456789"}) as ws:
            ws.recv(timeout=10)


def test_one_stream_at_a_time_and_a_leaving_client_frees_its_slot(url) -> None:
    first = connect(url, additional_headers=AUTH)
    assert _start(first, realtime=True)["type"] == "ready"
    with connect(url, additional_headers=AUTH) as second:
        closed = _closed(second)
        assert closed.rcvd.code == 1013 and "try again later" in closed.rcvd.reason
    first.close()  # the client goes away mid-stream
    deadline = time.monotonic() + 30
    while True:
        with connect(url, additional_headers=AUTH) as third:
            try:  # until the server has noticed the first client left, it refuses with 1013
                third.send(json.dumps({"type": "start", "realtime": False, "seconds": 0.5}))
                if json.loads(third.recv(timeout=60))["type"] == "ready":
                    break
            except ConnectionClosed:
                pass
        assert time.monotonic() < deadline, "the slot of a client that left was not freed"
        time.sleep(0.5)
