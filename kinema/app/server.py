"""The app server: one viser server, one loaded model shared by every tab, a small worker pool for
generation, and a Session per connected tab."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import viser

from kinema.app.camera import opening_view
from kinema.app.generation import AppRobot, is_any_rig
from kinema.app.rigs import AppRig, model_rig
from kinema.app.session import Session
from kinema.app.views import first_motions
from kinema.errors import KinemaError

#: generations that may run at once (across tabs); more wait in the pool's queue
WORKERS = 2
#: where a new tab's camera stands and looks (world metres, Y up): to the character's left (+X), above
#: the first metres of a walk along +Z, so that paths across the ground read left to right
CAMERA_POSITION = (4.4, 4.6, 1.0)
CAMERA_LOOK_AT = (0.0, 0.2, 3.4)


class AppServer:
    """``kinema app``: serve the authoring UI for ``model`` on ``host:port`` (``steps``: DDIM steps
    a new tab starts with, None = the model's setting; ``rig``: the character new tabs show, default
    the model's own skeleton; ``model_name`` names the model in messages; ``robot``: a robot every
    generated motion is also retargeted onto and drawn beside it, kinema app --robot)."""

    def __init__(
        self,
        model,
        *,
        rig: AppRig | None = None,
        model_name: str = "default",
        host: str = "127.0.0.1",
        port: int = 8080,
        steps: int | None = None,
        robot: AppRobot | None = None,
        verbose: bool = False,
    ):
        if rig is None and is_any_rig(model):
            raise KinemaError("an any-rig model needs a rig to start with: kinema app --model creatures --rig FILE")
        if robot is not None and is_any_rig(model):
            raise KinemaError("--robot: robots are retargeted from the human model's motions; drop --model creatures")
        self.model, self.steps, self.model_name, self.robot = model, steps, model_name, robot
        self.rig = rig or model_rig(model.skeleton, name=model_name)
        self.pool = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="kinema-app-generate")
        self.sessions: dict[int, Session] = {}
        self._lock = threading.Lock()
        self.server = viser.ViserServer(host=host, port=port, label="kinema", verbose=verbose)
        self.server.scene.set_up_direction("+y")
        # a new tab starts framed on what it shows first (a page may set up its starting view after the
        # tab's own framing reached it: on a loaded machine most did, leaving the character in a corner)
        start = self.server.initial_camera
        start.position, start.look_at = opening_view(first_motions(self.rig, model.fps)[0], float(start.fov))
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def _connect(self, client) -> None:
        session = Session(self, client)
        with self._lock:
            self.sessions[client.client_id] = session

    def _disconnect(self, client) -> None:
        with self._lock:
            session = self.sessions.pop(client.client_id, None)
        if session is not None:
            session.close()

    def stop(self) -> None:
        for session in list(self.sessions.values()):
            session.close()
        self.server.stop()
        self.pool.shutdown(wait=False, cancel_futures=True)
