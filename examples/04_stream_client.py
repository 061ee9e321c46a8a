"""A live stream over WebSocket from `kinema serve` (kinema/server/stream.py, docs/stream.md).

    python examples/04_stream_client.py      # starts a local `kinema serve` for itself
    KINEMA_STREAM_URL=ws://127.0.0.1:8000/v1/stream KINEMA_API_KEY=KEY python examples/04_stream_client.py

Frames arrive at the playback rate as JSON (root translation, local rotations w-x-y-z, positions);
commands are sent while it plays (a turn to the right at 3 s, a bow at 6 s) and answered with how many
seconds of motion later the stream obeys them. The frames are written as a kinema .npz
(out/stream_client.npz; `kinema render out/stream_client.npz --out film.png` draws it).
Needs the `websockets` package (installed with the server's dependencies).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from websockets.sync.client import connect

#: seconds of motion received -> the command sent then
SCRIPT = {3.0: {"type": "steer", "direction_deg": 90, "speed": 1.2}, 6.0: {"type": "prompt", "text": "A person bows."}}


@contextmanager
def local_server():
    """A `kinema serve` on a free loopback port for the length of the block; yields its stream URL."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "kinema", "serve", "--port", str(port), "--threads", "1",
                             "--log-level", "warning"], start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.3)
        yield f"ws://127.0.0.1:{port}/v1/stream"
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(30)


def stream(url: str, key: str | None, seconds: float) -> tuple[dict, list, list, list]:
    """Stream ``seconds`` of motion, sending `SCRIPT` on the way; the skeleton and the frames."""
    headers = {"Authorization": f"Bearer {key}"} if key else None
    script, roots, rotations, positions = dict(SCRIPT), [], [], []
    with connect(url, additional_headers=headers, open_timeout=60) as ws:
        ws.send(json.dumps({"type": "start", "prompt": "A person walks forward.", "seconds": seconds}))
        ready = json.loads(ws.recv())
        for message in ws:
            data = json.loads(message)
            if data["type"] == "frames":
                roots += data["root_translation"]
                rotations += data["local_rotations"]
                positions += data["positions"]
                for t in [t for t in script if t <= len(roots) / data["fps"]]:
                    ws.send(json.dumps(script.pop(t)))
            elif data["type"] == "command":
                print(f"{data['kind']} sent at {data['issued_seconds']:.2f} s of motion: obeyed from "
                      f"{data['latency_seconds']:.2f} s later")
            elif data["type"] == "end":
                break
    return ready, roots, rotations, positions


def main(seconds: float = 9.0) -> None:
    url = os.environ.get("KINEMA_STREAM_URL")
    if url:
        ready, roots, rotations, positions = stream(url, os.environ.get("KINEMA_API_KEY"), seconds)
    else:
        with local_server() as url:
            ready, roots, rotations, positions = stream(url, None, seconds)
    out = Path("out/stream_client.npz")
    out.parent.mkdir(exist_ok=True)
    np.savez_compressed(out, joint_names=np.array(ready["joints"]), parents=np.array(ready["parents"]),
                        offsets=np.array(ready["offsets"]), fps=np.array(ready["fps"]),
                        root_translation=np.array(roots, np.float32), local_quats=np.array(rotations, np.float32),
                        positions=np.array(positions, np.float32))
    print(f"wrote {out}: {len(roots)} frames at {ready['fps']:g} fps, {len(ready['joints'])} joints")


if __name__ == "__main__":
    main()
