"""`kinema serve`: the HTTP API (FastAPI + uvicorn) around one or more loaded models.

Everything is checked before a model is loaded or a port is bound: a non-loopback ``--host`` needs
``--api-key-file``, limits must be positive. Generation runs on ``--workers`` threads sharing the
loaded models; docs/server.md documents the endpoints and every limit.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import add_precision_argument, non_negative_int, positive_float, positive_int

MISSING_EXTRA = "kinema serve needs the server extra: pip install 'kinema[server]' (fastapi, uvicorn)"


def _port(text: str) -> int:
    n = non_negative_int(text)
    if not 1 <= n <= 65535:
        raise argparse.ArgumentTypeError(f"expected a TCP port 1..65535, got {n}")
    return n


def register(sub) -> None:
    from kinema.server.config import ServerLimits

    d = ServerLimits()
    p = sub.add_parser("serve", help="HTTP API for tools and game engines (docs/server.md)", description=__doc__)
    p.add_argument("--model", action="append", metavar="SPEC",
                   help="'default' (shipped), a run/checkpoint folder, or NAME=FOLDER; repeat to serve several "
                        "(the first is the default); default: default")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1; any non-loopback "
                   "address needs --api-key-file)")
    p.add_argument("--port", type=_port, default=8000, help="TCP port (default 8000)")
    p.add_argument("--workers", type=positive_int, default=d.workers,
                   help=f"generation threads sharing the loaded models (default {d.workers})")
    p.add_argument("--queue", type=non_negative_int, default=d.queue,
                   help=f"requests that may wait for a worker; more get 429 + Retry-After (default {d.queue})")
    p.add_argument("--api-key-file", type=Path, help="file with API key(s), one per line; clients send "
                   "'Authorization: Bearer KEY' or 'X-API-Key: KEY' to /v1/*")
    p.add_argument("--cors-origin", action="append", default=[], metavar="ORIGIN",
                   help="allow browser calls from ORIGIN (repeatable; default: CORS off)")
    p.add_argument("--max-seconds", type=positive_float, default=d.max_seconds,
                   help=f"longest output per request, seconds (default {d.max_seconds:g})")
    p.add_argument("--max-samples", type=positive_int, default=d.max_samples, help=f"default {d.max_samples}")
    p.add_argument("--max-steps", type=positive_int, default=d.max_steps, help=f"default {d.max_steps}")
    p.add_argument("--max-body-bytes", type=positive_int, default=d.max_body_bytes,
                   help=f"largest request body (default {d.max_body_bytes}); 413 above")
    p.add_argument("--timeout", type=positive_float, default=d.timeout_s,
                   help=f"seconds POST /v1/generate waits for its result (default {d.timeout_s:g}); 504 after")
    p.add_argument("--read-timeout", type=positive_float, default=d.read_timeout_s,
                   help=f"seconds to wait for the next part of a request body (default {d.read_timeout_s:g}); "
                   "408 after")
    p.add_argument("--max-jobs", type=positive_int, default=d.max_jobs, help=f"jobs kept (default {d.max_jobs})")
    p.add_argument("--job-ttl", type=positive_float, default=d.job_ttl_s,
                   help=f"seconds a finished job's result is kept (default {d.job_ttl_s:g})")
    p.add_argument("--threads", type=positive_int, help="torch CPU threads in all (default: KINEMA_THREADS, else "
                   "kinema.runtime's choice)")
    p.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    add_precision_argument(p)
    p.set_defaults(func=run)


def build_config(args: argparse.Namespace):
    """The ServerConfig the arguments describe (raises KinemaError before anything is loaded)."""
    from kinema.server.config import ServerConfig, ServerLimits, read_api_keys

    limits = ServerLimits(max_seconds=args.max_seconds, max_samples=args.max_samples, max_steps=args.max_steps,
                          max_body_bytes=args.max_body_bytes, workers=args.workers, queue=args.queue,
                          timeout_s=args.timeout, max_jobs=args.max_jobs, job_ttl_s=args.job_ttl,
                          read_timeout_s=args.read_timeout)
    keys = read_api_keys(args.api_key_file) if args.api_key_file is not None else ()
    return ServerConfig(host=args.host, port=args.port, api_keys=keys, cors_origins=tuple(args.cors_origin),
                        limits=limits)


def run(args: argparse.Namespace) -> int:
    from kinema.errors import KinemaError

    config = build_config(args)
    try:
        import uvicorn

        from kinema.server.app import create_app
    except ImportError as err:
        raise KinemaError(f"{MISSING_EXTRA} ({err})") from None
    from kinema.runtime import configure_threads
    from kinema.server.models import ModelRegistry

    configure_threads(args.threads)
    registry = ModelRegistry.load(args.model or ["default"])
    app = create_app(config, registry)
    print(f"kinema serve: models {registry.names} on http://{config.host}:{config.port} "
          f"({config.limits.workers} worker(s), queue {config.limits.queue}; docs at /docs)", flush=True)
    uvicorn.run(app, host=config.host, port=config.port, log_level=args.log_level, timeout_keep_alive=5)
    return 0
