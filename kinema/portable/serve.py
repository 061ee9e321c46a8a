"""``kinema web``: serve the browser page (``web/``) and an exported model folder over local HTTP.

The page is static: ``web/`` with its built ``vendor/`` (``npm ci && npm run build`` in ``web/``) and the
exported folder under ``model/``. Here the folder is served from wherever it lies (``--model-dir``, else
the shipped model's export in kinema's cache, made on first use), so nothing is copied; on a static host,
copy the export into ``web/model/``.
"""

from __future__ import annotations

import functools
import http.server
import threading
from pathlib import Path

from kinema.errors import KinemaError
from kinema.portable.manifest import FILE_NAME

#: the page's folder in kinema's source tree
WEB_DIR = Path(__file__).resolve().parents[2] / "web"
#: what the page loads from vendor/ (web/build.mjs copies them there)
VENDOR_FILES = ("ort.wasm.min.mjs", "ort-wasm-simd-threaded.wasm", "three.module.min.js", "OrbitControls.js")


def check_page(web_dir: Path = WEB_DIR) -> Path:
    """``web_dir`` when it holds the page and its built vendor files, else a one-line `KinemaError`."""
    if not (web_dir / "index.html").is_file():
        raise KinemaError(f"{web_dir}: the page (web/index.html) is not there; it comes with kinema's source tree")
    missing = [f for f in VENDOR_FILES if not (web_dir / "vendor" / f).is_file()]
    if missing:
        raise KinemaError(f"{web_dir}/vendor lacks {', '.join(missing)}: run `npm ci && npm run build` in {web_dir}")
    return web_dir


def check_model_dir(folder: Path) -> Path:
    if not (Path(folder) / FILE_NAME).is_file():
        raise KinemaError(f"{folder}: not an exported model folder (no {FILE_NAME}; make one with kinema export-onnx)")
    return Path(folder)


class _Handler(http.server.SimpleHTTPRequestHandler):
    """Static files of the page, with ``/model/...`` read from the model folder."""

    extensions_map = {**http.server.SimpleHTTPRequestHandler.extensions_map, ".mjs": "text/javascript",
                      ".js": "text/javascript", ".wasm": "application/wasm", ".onnx": "application/octet-stream"}

    def __init__(self, *args, model_dir: Path, **kwargs):
        self.model_dir = model_dir
        super().__init__(*args, **kwargs)

    def translate_path(self, path: str) -> str:
        clean = path.split("?", 1)[0].split("#", 1)[0]
        if clean.startswith("/model/"):
            name = clean[len("/model/"):]
            target = (self.model_dir / name).resolve()
            if target.parent == self.model_dir.resolve():  # the folder's own files only
                return str(target)
            return str(self.model_dir / "..missing")
        return super().translate_path(path)

    def log_message(self, format, *args):  # quiet: the page loads many files
        pass


class _QuietServer(http.server.ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request, client_address):  # a browser closing a connection early is no error
        import sys

        if not isinstance(sys.exc_info()[1], ConnectionError):
            super().handle_error(request, client_address)


class WebServer:
    """The page on ``http://host:port/``: in a background thread (``stop()`` ends it), or, with
    ``background=False``, in the caller's thread by :meth:`serve`."""

    def __init__(self, model_dir: Path, host: str = "127.0.0.1", port: int = 8765, web_dir: Path = WEB_DIR,
                 background: bool = True):
        web_dir, model_dir = check_page(web_dir), check_model_dir(model_dir)
        handler = functools.partial(_Handler, directory=str(web_dir), model_dir=model_dir.resolve())
        try:
            self.httpd = _QuietServer((host, port), handler)
        except (OSError, OverflowError) as err:  # OverflowError: a port outside 0-65535
            raise KinemaError(f"cannot listen on {host}:{port}: {getattr(err, 'strerror', None) or err}") from None
        self.url = f"http://{host}:{self.httpd.server_address[1]}/"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True) if background else None
        if self.thread is not None:
            self.thread.start()

    def serve(self) -> None:
        """Serve in this thread until interrupted (Ctrl-C), then close the socket."""
        try:
            self.httpd.serve_forever()
        finally:
            self.httpd.server_close()

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
