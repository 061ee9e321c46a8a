"""`kinema app`: the web authoring UI (viser), docs/app.md.

Loads the model, starts the server and prints the URL; runs until interrupted. Needs the app extra:
pip install 'kinema[app]'.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from kinema.cli._args import add_precision_argument, positive_int
from kinema.cli.serve import _port
from kinema.errors import KinemaError
from kinema.server.config import is_loopback

MISSING_EXTRA = "kinema app needs the app extra: pip install 'kinema[app]' (viser)"


def register(sub) -> None:
    p = sub.add_parser(
        "app",
        help="web authoring UI: timeline, constraints in the scene, playback, export (docs/app.md)",
        description=__doc__,
    )
    p.add_argument(
        "--model",
        default="default",
        help="'default' (human), 'creatures' (any rig: needs --rig) or a checkpoint folder",
    )
    p.add_argument(
        "--rig",
        type=Path,
        help="a .glb/.gltf (skin + clips) or .bvh rig new tabs show (default: the model's skeleton)",
    )
    p.add_argument(
        "--rig-units",
        choices=("centimetres", "metres", "inches"),
        default="centimetres",
        help="length unit of a .bvh --rig (default centimetres)",
    )
    p.add_argument(
        "--robot",
        help="also retarget every generated motion onto a robot and draw it beside the human: 'g1', 'h1' or an MJCF "
        "file (docs/robots.md; human model only)",
    )
    p.add_argument("--mapping", type=Path, help="with --robot: JSON landmark -> body mapping of an MJCF whose body "
                   "names kinema does not recognise (docs/robots.md)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only; "
                   "another address needs --public)")
    p.add_argument("--public", action="store_true", help="allow a --host other than loopback: the app has no "
                   "login, so anyone who can reach the address can use it and its CPU")
    p.add_argument("--port", type=_port, default=8080, help="TCP port (default 8080; the next free one if taken)")
    p.add_argument(
        "--steps",
        type=positive_int,
        help="DDIM steps new tabs start with (default: the model's setting; fewer = faster drafts)",
    )
    p.add_argument(
        "--threads", type=positive_int, help="torch CPU threads (default: KINEMA_THREADS, else kinema.runtime's choice)"
    )
    add_precision_argument(p)
    p.set_defaults(func=run)


def check_host(host: str, public: bool) -> None:
    """Refuse a non-loopback bind unless ``--public`` says so: unlike `kinema serve` (API keys), the app
    has no login to protect it."""
    if not is_loopback(host) and not public:
        raise KinemaError(f"--host {host} is not a loopback address and the app has no login: anyone who can reach "
                          "it could use it; bind to 127.0.0.1 (an SSH tunnel reaches it from elsewhere) or add "
                          "--public to accept that")


def run(args: argparse.Namespace) -> int:
    check_host(args.host, args.public)
    if args.public and not is_loopback(args.host):
        print(f"kinema app: warning: --public: anyone who can reach {args.host} can use this app", flush=True)
    try:
        from kinema.app.generation import AppRobot, max_steps
        from kinema.app.server import AppServer
    except ImportError as err:
        if "viser" not in str(err):
            raise
        raise KinemaError(MISSING_EXTRA) from None
    from kinema.app.files_panel import UNITS
    from kinema.app.rigs import load_rig
    from kinema.generate import load_model
    from kinema.input_files import check_input_file
    from kinema.robot import load_robot
    from kinema.runtime import configure_threads

    if args.rig is not None:
        check_input_file(args.rig, "rig file")
    configure_threads(args.threads)
    model = load_model(args.model)
    rig = None if args.rig is None else load_rig(args.rig, fps=model.fps, scale=UNITS[args.rig_units])
    if args.steps is not None and args.steps > max_steps(model):
        raise KinemaError(f"--steps: at most {max_steps(model)} for this model, got {args.steps}")
    if args.mapping is not None and args.robot is None:
        raise KinemaError("--mapping names the bodies of a --robot MJCF; give --robot too")
    robot = None if args.robot is None else AppRobot(args.robot, load_robot(args.robot, mapping=args.mapping),
                                                     args.mapping)
    app = AppServer(model, rig=rig, model_name=str(args.model), host=args.host, port=args.port, steps=args.steps,
                    robot=robot)
    print(f"kinema app: open {app.url} (Ctrl+C to stop)", flush=True)
    try:
        while True:
            time.sleep(3600)
    finally:
        app.stop()
