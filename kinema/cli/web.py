"""`kinema web [--model-dir DIR]`: the page that generates in the browser (onnxruntime-web), served locally.

Serves ``web/`` with an exported model folder (``kinema export-onnx``) under ``model/``: ``--model-dir``,
else the shipped model, exported into kinema's cache on first use (a minute or two). See
docs/onnx_runtime.md; the page needs its vendor files built once (``npm ci && npm run build`` in web/).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub) -> None:
    """Add the `web` sub-command to the top-level parser."""
    p = sub.add_parser("web", help="serve the in-browser generation page (ONNX export + onnxruntime-web)",
                       description=__doc__)
    p.add_argument("--model-dir", type=Path, help="an exported folder (default: the shipped model, exported once)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8765, help="port (default 8765; 0 picks a free one)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.portable.serve import WebServer, check_page

    check_page()
    if args.model_dir is None:
        from kinema.portable.cache import cached_export

        print("exporting the shipped model on first use (kinema's cache)…", flush=True)
        model_dir = cached_export("default")
    else:
        model_dir = args.model_dir
    server = WebServer(model_dir, args.host, args.port, background=False)
    print(f"kinema web: {server.url} (model {model_dir}); Ctrl-C stops", flush=True)
    server.serve()
