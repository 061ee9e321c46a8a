"""Measure how far CPU float noise moves the reference cases of tests/reference_cases.py.

Runs every case in a fresh process per setting, each emulating a different CPU or library path:
thread counts (torch.set_num_threads), ATen's vector kernels (``ATEN_CPU_CAPABILITY`` default / avx2
/ avx512), MKL's code path (``MKL_ENABLE_INSTRUCTIONS``, ``MKL_CBWR``) and oneDNN's
(``ONEDNN_MAX_CPU_ISA``), and prints, per case and field, the largest difference of each setting's
outputs from tests/data/reference_outputs.npz (millimetres, degrees, contact probability). The
bounds of tests/test_reference_outputs.py are derived from this table (see its docstring).

``python scripts/measure_reference_spread.py [--out out/reference_spread.json]``
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path.insert(0, str(TESTS))

from reference_cases import cases  # noqa: E402
from reference_compare import FIELDS, differences, motion_arrays, recorded, sample_count  # noqa: E402

import kinema  # noqa: E402

FIXTURE = TESTS / "data" / "reference_outputs.npz"

# name -> (threads, environment); each emulates another CPU's (or build's) float path
SETTINGS = {
    "1 thread": (1, {}),
    "2 threads": (2, {}),
    "aten default": (1, {"ATEN_CPU_CAPABILITY": "default"}),
    "aten avx2": (1, {"ATEN_CPU_CAPABILITY": "avx2"}),
    "aten avx512": (1, {"ATEN_CPU_CAPABILITY": "avx512"}),
    "mkl avx2": (1, {"MKL_ENABLE_INSTRUCTIONS": "AVX2"}),
    "mkl sse4.2": (1, {"MKL_ENABLE_INSTRUCTIONS": "SSE4_2"}),
    "mkl cbwr compatible": (1, {"MKL_CBWR": "COMPATIBLE"}),
    "onednn avx2": (1, {"ONEDNN_MAX_CPU_ISA": "AVX2"}),
    "onednn sse41": (1, {"ONEDNN_MAX_CPU_ISA": "SSE41"}),
    "old cpu (all sse, 2 threads)": (
        2,
        {
            "ATEN_CPU_CAPABILITY": "default",
            "MKL_ENABLE_INSTRUCTIONS": "SSE4_2",
            "ONEDNN_MAX_CPU_ISA": "SSE41",
        },
    ),
    "avx2 cpu (all avx2)": (
        1,
        {"ATEN_CPU_CAPABILITY": "avx2", "MKL_ENABLE_INSTRUCTIONS": "AVX2", "ONEDNN_MAX_CPU_ISA": "AVX2"},
    ),
}


def emit(out: str, threads: int) -> None:
    """Generate every case in this process and save its arrays to ``out``."""
    torch.set_num_threads(threads)
    model = kinema.load_model(precision="fp32")
    with np.load(FIXTURE) as data:
        todo = cases(data["input_kf_rot"], data["input_kf_root"])
    arrays = {}
    for name, prompt, kwargs in todo:
        for i, m in enumerate(model.generate(prompt, **kwargs)):
            arrays.update({f"{name}_{i}_{k}": v for k, v in motion_arrays(m).items()})
    np.savez(out, **arrays)


def run_setting(threads: int, env: dict[str, str], out: Path) -> None:
    full = {**os.environ, **env, "OMP_NUM_THREADS": str(threads)}
    cmd = [sys.executable, __file__, "--emit", str(out), str(threads)]
    subprocess.run(cmd, env=full, check=True)


def spread(reference: dict, outputs: dict) -> dict:
    """{setting: {case: {field: max difference from the fixture}}}."""
    keys = [k.rsplit("_", 2) for k in reference if k.endswith("_root")]
    names = sorted({parts[0] for parts in keys if parts[1].isdigit()})
    table = {}
    for setting, got in outputs.items():
        table[setting] = {}
        for name in names:
            worst = dict.fromkeys(FIELDS, 0.0)
            for i in range(sample_count(reference, name)):
                d = differences(recorded(got, name, i), recorded(reference, name, i))
                worst = {f: max(worst[f], d[f]) for f in FIELDS}
            table[setting][name] = worst
    return table


def main(out_json: str | None) -> None:
    with np.load(FIXTURE) as data:
        reference = {k: data[k] for k in data.files}
    outputs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for setting, (threads, env) in SETTINGS.items():
            path = Path(tmp) / f"{len(outputs)}.npz"
            run_setting(threads, env, path)
            with np.load(path) as data:
                outputs[setting] = {k: data[k] for k in data.files}
    table = spread(reference, outputs)
    print(f"{'setting':32s} {'case':16s} " + " ".join(f"{f:>10s}" for f in FIELDS))
    for setting, rows in table.items():
        for name, worst in rows.items():
            print(f"{setting:32s} {name:16s} " + " ".join(f"{worst[f]:10.3g}" for f in FIELDS))
    overall = {f: max(r[f] for rows in table.values() for r in rows.values()) for f in FIELDS}
    print("largest over all settings and cases: " + ", ".join(f"{f} {v:.3g}" for f, v in overall.items()))
    if out_json:
        Path(out_json).parent.mkdir(parents=True, exist_ok=True)
        Path(out_json).write_text(json.dumps({"settings": table, "largest": overall}, indent=1))


if __name__ == "__main__":
    args = sys.argv[1:]
    if args and args[0] == "--emit":
        emit(args[1], int(args[2]))
    else:
        main(args[1] if len(args) == 2 and args[0] == "--out" else None)
