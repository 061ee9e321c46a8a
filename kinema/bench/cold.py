"""Cold-start benchmarks: the first `kinema generate` of a fresh process, whole and phase by phase.

Why: a user's first command pays for the interpreter, imports, model and text-encoder load and an empty
text cache on top of sampling; only a fresh process in an empty working directory measures that.
``cli_times`` runs the real CLI twice in a temporary cwd (cold: an empty text cache, a prompt never seen
before; warm: the same command again, text cache filled, OS file cache hot). ``phase_breakdown`` runs the
pieces of ``KinemaModel.generate`` one by one in a fresh interpreter with ``perf_counter`` between them,
without touching kinema.generate: imports, model load, text encoding (first prompt), sampling (DDIM and
features -> motion), post-processing and writing the BVH; interpreter start-up is the rest of the wall time.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

from kinema.runtime import CACHE_ENV_VAR, text_cache_dir

#: Phases reported by phase_breakdown, in order.
PHASES = ("startup", "imports", "model_load", "text_encoding", "sampling", "postprocess", "writing")


def _env(threads: int | None, cwd: str) -> dict[str, str]:
    """The child's environment: ours, with ``KINEMA_THREADS`` set when a thread count is asked for and
    the text cache in the temporary ``cwd`` (empty at first, as on a fresh machine)."""
    env = dict(os.environ) | {CACHE_ENV_VAR: str(Path(cwd) / "cache")}
    if threads is not None:
        env["KINEMA_THREADS"] = str(threads)
    return env


def unique_prompt() -> str:
    """A prompt no text cache holds yet, so the text encoder really runs."""
    return f"A person walks forward and waves {uuid.uuid4().hex[:8]} times."


def cli_times(model: str, seconds: float = 5.0, threads: int | None = None, steps: int | None = None) -> dict:
    """Wall seconds of ``kinema generate "<new prompt>" --seconds S`` cold, then the same command warm."""
    prompt = unique_prompt()
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="kinema-bench-") as cwd:
        cmd = [sys.executable, "-m", "kinema", "generate", prompt, "--seconds", f"{seconds:g}", "--model", model,
               "--out", str(Path(cwd) / "out.bvh"), "--no-progress"]
        if steps is not None:
            cmd += ["--steps", str(steps)]
        for key in ("cold_s", "warm_s"):
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, cwd=cwd, env=_env(threads, cwd), capture_output=True, text=True)
            out[key] = time.perf_counter() - t0
            if proc.returncode != 0:
                raise RuntimeError(f"kinema generate failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return out


def run_phases(model: str, prompt: str, seconds: float, steps: int | None, out_path: str) -> dict:
    """In-process part of :func:`phase_breakdown` (kinema already imported); returns seconds per phase.

    One ``generate`` call of one sample of one prompt; its report's timings split sampling from post-processing.
    """
    from kinema.generate import GenerationRequest, load_model

    times: dict[str, float] = {}
    t0 = time.perf_counter()
    m = load_model(model, text_cache=text_cache_dir())
    times["model_load"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    m.encode_text(prompt)  # first prompt: loads the encoder weights, encodes, fills the cache
    times["text_encoding"] = time.perf_counter() - t0
    result = m.generate(GenerationRequest(prompt=prompt, seconds=seconds, steps=steps))
    times["sampling"] = result.report.timings["sampling"]
    times["postprocess"] = result.report.timings["postprocess"]
    motion = result[0]
    t0 = time.perf_counter()
    motion.save(out_path)
    times["writing"] = time.perf_counter() - t0
    return times


_CHILD = """
import json, sys, time
t0 = time.perf_counter()
import kinema.cli, kinema.human.pipeline
imports = time.perf_counter() - t0
from kinema.runtime import configure_threads
configure_threads()
from kinema.bench.cold import run_phases
times = run_phases(*json.loads(sys.argv[1]))
times["imports"] = imports
print("KINEMA_PHASES " + json.dumps(times))
"""


def phase_breakdown(model: str, seconds: float = 5.0, threads: int | None = None, steps: int | None = None) -> dict:
    """Seconds per phase (:data:`PHASES`) of a first generation in a fresh process with an empty text cache."""
    with tempfile.TemporaryDirectory(prefix="kinema-bench-") as cwd:
        args = json.dumps([model, unique_prompt(), seconds, steps, str(Path(cwd) / "out.bvh")])
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", _CHILD, args], cwd=cwd, env=_env(threads, cwd),
                              capture_output=True, text=True)
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"phase breakdown failed ({proc.returncode}): {proc.stderr[-2000:]}")
    line = next(x for x in proc.stdout.splitlines() if x.startswith("KINEMA_PHASES "))
    times = json.loads(line.split(" ", 1)[1])
    times["startup"] = max(0.0, wall - sum(times.values()))
    return {"total": wall, **{k: times[k] for k in PHASES}}


def format_cold(cli: dict | None, phases: dict | None) -> str:
    """The cold/warm CLI line and the phase table."""
    lines = []
    if cli:
        lines.append(f"kinema generate (new process, 5-s motion): cold {cli['cold_s']:.2f} s (empty text cache, "
                     f"new prompt), warm {cli['warm_s']:.2f} s (same command again)")
    if phases:
        lines += ["", f"{'phase (fresh process)':<24}{'seconds':>9}{'share':>8}", "-" * 41]
        for k in PHASES:
            lines.append(f"{k:<24}{phases[k]:>9.3f}{phases[k] / phases['total']:>8.0%}")
        lines.append(f"{'total':<24}{phases['total']:>9.3f}")
    return "\n".join(lines)
