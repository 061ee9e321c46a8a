"""The worker side of `kinema batch`: load the model once per process, then turn payloads into file bytes.

Why bytes back to the driver instead of files written here: the driver alone writes outputs (atomically)
and the manifest, so a worker on another machine needs no shared output folder, and a crash can never
leave a file without knowing which job it belongs to. Workers return errors as data (never raise for a
bad job), so one bad line cannot take a worker down and every error crosses process boundaries intact.
"""

from __future__ import annotations

import os
import socket
import tempfile
import time
import traceback
from pathlib import Path

from kinema.errors import KinemaError
from kinema.generate import load_model
from kinema.model.fingerprint import model_sha256
from kinema.pipeline.request import GenerationRequest
from kinema.pipeline.result import json_safe
from kinema.runtime import configure_threads


class Worker:
    """Loaded models (the run's, and any a job names) with their fingerprints; `run` does one job. Used
    in-process, per pool process, per Ray actor."""

    def __init__(self, model_spec: str, threads: int = 1):
        configure_threads(threads)
        self.default = model_spec
        self.models: dict[str, tuple[object, str]] = {}
        self._model(model_spec)
        self.name = f"{socket.gethostname()}:{os.getpid()}"

    def _model(self, spec: str):
        """(pipeline, sha256) of a model spec, loaded once per process."""
        if spec not in self.models:
            model = load_model(spec)
            self.models[spec] = (model, model_sha256(model.path))
        return self.models[spec]

    @property
    def sha256(self) -> str:
        return self.models[self.default][1]

    def ping(self) -> str:
        """This worker's name (host:pid), once its model is loaded (warm-up and start-up timing)."""
        return self.name

    def run(self, payload: dict) -> dict:
        """Generate one job: ``{"files": [bytes, ...], "report": {...}, ...}`` or ``{"error": ...}``."""
        t0 = time.perf_counter()
        base = {"worker": self.name}
        try:
            model, sha = self._model(payload.get("model") or self.default)
            base["model_sha256"] = sha
            result = model.generate(GenerationRequest.from_json(payload["request"]))
            files = _encode(result.robot_motions or list(result), payload["outputs"])
        except KinemaError as err:
            return base | {"error": str(err), "error_type": type(err).__name__}
        except Exception as err:  # a bug, reported per job (with its traceback) instead of killing the worker
            return base | {"error": f"{type(err).__name__}: {err}", "error_type": "internal",
                           "traceback": traceback.format_exc(limit=8)}
        rep = result.report
        report = {"seconds": result[0].duration, "frames": rep.frames, "steps": rep.steps,
                  "guidance": list(rep.guidance), "guidance_mode": rep.guidance_mode, "seed": rep.seed,
                  "residuals": json_safe(rep.residuals),
                  "warnings": [str(w) for w in rep.warnings]}
        return base | {"files": files, "report": report, "elapsed_s": time.perf_counter() - t0}


def _encode(motions, names: list[str]) -> list[bytes]:
    """Each motion (or robot motion) as the bytes its ``save`` writes for its output name (format from the
    suffix)."""
    out = []
    with tempfile.TemporaryDirectory(prefix="kinema-batch-") as tmp:
        for motion, name in zip(motions, names, strict=True):
            path = motion.save(Path(tmp) / name)
            out.append(path.read_bytes())
    return out


# ----------------------------------------------------------------------------- process-pool entry points
_WORKER: Worker | None = None


def init_process(model_spec: str, threads: int) -> None:
    """ProcessPoolExecutor initializer: load the model once; Ctrl-C is the driver's to handle; exit when
    the driver is gone (killed or crashed: a pool process would otherwise wait for work forever)."""
    import signal
    import threading

    global _WORKER
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True, name="kinema-parent-watch").start()
    _WORKER = Worker(model_spec, threads)


def _exit_with_parent(parent: int, every: float = 0.5) -> None:
    """End this process once its parent has died (it is then re-parented, so ``getppid`` changes)."""
    while os.getppid() == parent:
        time.sleep(every)
    os._exit(1)


def process_ping() -> str:
    assert _WORKER is not None
    return _WORKER.ping()


def process_run(payload: dict) -> dict:
    assert _WORKER is not None
    return _WORKER.run(payload)
