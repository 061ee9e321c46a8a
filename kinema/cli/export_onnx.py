"""`kinema export-onnx MODEL --out DIR`: the human model as ONNX graphs plus one runtime JSON.

Writes the guided denoiser (and the action expert's) with float32 and float16-stored weights, the MiniLM
text encoder with its tokenizer files, and ``kinema_runtime.json`` (kinema.portable.export,
docs/onnx_runtime.md). Needs the onnx extra: ``pip install 'kinema[onnx]'``.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub) -> None:
    """Add the `export-onnx` sub-command to the top-level parser."""
    p = sub.add_parser("export-onnx", help="export the human model as ONNX graphs + runtime JSON (browser, engines)",
                       description=__doc__)
    p.add_argument("model", help="'default' or a trained human model / run / checkpoint folder")
    p.add_argument("--out", type=Path, required=True, help="folder to write (created; its files are replaced)")
    p.add_argument("--no-fp16", action="store_true", help="skip the float16-weight copies of the graphs")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.portable.export import export_onnx

    result = export_onnx(args.model, args.out, fp16=not args.no_fp16)
    graphs = result.manifest["graphs"] | {"text_encoder": result.manifest["text_encoder"]}
    for name, entry in graphs.items():
        half = f", fp16 weights {entry['fp16_max_abs_error']:.2g}" if "fp16" in entry else ""
        print(f"{name}: {entry['fp32']} (probe error fp32 {entry['fp32_max_abs_error']:.2g}{half})")
    print(f"wrote {result.folder} ({result.size_bytes / 1e6:.1f} MB)")
    return 0
