"""``kinema export-onnx MODEL --out DIR``: the human model as ONNX graphs plus one runtime JSON.

The folder it writes (docs/onnx_runtime.md):

- ``denoiser.onnx``: the guided two-stage denoiser (kinema.portable.graphs), float32;
- ``action_expert.onnx``: the same graph with the action expert's weights, when the model has one;
- ``text_encoder.onnx``: MiniLM (token ids -> unit sentence embedding), with ``tokenizer.json`` and
  ``vocab.txt`` (BERT WordPiece, lower-cased);
- ``*.fp16.onnx``: each graph with its weights stored in float16 (float32 arithmetic), half the size; the
  JSON records how far each strays from its float32 graph on a probe input;
- ``kinema_runtime.json`` (kinema.portable.manifest) and ``LICENSE.txt``.

Every graph is checked against the PyTorch network it came from on a probe input before the folder is
written; a graph that differs by more than :data:`CHECK_TOLERANCE` is an error.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from kinema.errors import KinemaError
from kinema.generate.loading import pipeline_name, resolve_model_path
from kinema.model.loading import LoadedModel, find_checkpoint, load_denoiser, read_checkpoint_info
from kinema.model.vocabulary import KnownPrompts
from kinema.portable.graphs import (
    DENOISER_INPUTS,
    ENCODER_INPUTS,
    OPSET,
    export_denoiser,
    export_encoder,
    fp16_weights,
    with_weights,
)
from kinema.portable.manifest import FILE_NAME, LICENSE, build_manifest

#: largest difference (normalised feature units / embedding units) between a float32 graph and its network
CHECK_TOLERANCE = 1e-3
#: the text encoder the export can write
MINILM_ID = "minilm-l6-v2"


@dataclass(frozen=True)
class OnnxExport:
    """What :func:`export_onnx` wrote: the folder, its runtime JSON and its size in bytes."""

    folder: Path
    manifest: dict
    size_bytes: int


def _probe(loaded: LoadedModel, frames: int = 40) -> dict[str, np.ndarray]:
    """A fixed guided-denoiser input: 2 branches (uncond, cond) of one motion, with a few constrained channels."""
    g = torch.Generator().manual_seed(0)
    cfg = loaded.denoiser.config
    T, D = min(frames, cfg.max_frames), cfg.feature_dim
    x = torch.randn(1, T, D, generator=g).repeat(2, 1, 1)
    text = torch.randn(1, cfg.text_dim, generator=g)
    text = torch.cat([torch.zeros_like(text), text / text.norm()])
    mask = torch.zeros(2, T, D)
    mask[1, ::7, :3] = 1.0
    tgt = torch.randn(2, T, D, generator=g) * mask
    return {"x_t": x.numpy(), "t": np.array([700, 700], dtype=np.int64), "text_emb": text.numpy(),
            "c_dir": np.array([[1.0, 0.0]] * 2, dtype=np.float32), "x_tgt": tgt.numpy(), "mask": mask.numpy(),
            "weights": np.array([-1.0, 2.0], dtype=np.float32)}


def _session(model_bytes: bytes):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.log_severity_level = 3
    return ort.InferenceSession(model_bytes, opts, providers=["CPUExecutionProvider"])


def _torch_guided(denoiser, feed: dict[str, np.ndarray]) -> np.ndarray:
    from kinema.portable.graphs import GuidedDenoiser

    with torch.no_grad():
        return GuidedDenoiser(denoiser)(*(torch.from_numpy(feed[n]) for n in DENOISER_INPUTS)).numpy()


def _check(name: str, got: np.ndarray, want: np.ndarray) -> float:
    err = float(np.abs(got - want).max())
    if not err <= CHECK_TOLERANCE:
        raise KinemaError(f"export-onnx: the {name} graph differs from the network by {err:.3g} (> {CHECK_TOLERANCE})")
    return err


def _write_graph(model, folder: Path, stem: str, feed: dict, want: np.ndarray, fp16: bool) -> dict:
    """``stem.onnx`` (and ``stem.fp16.onnx``), checked against ``want`` on ``feed``; their JSON entry."""
    import onnx

    data = model.SerializeToString()
    (folder / f"{stem}.onnx").write_bytes(data)
    entry = {"fp32": f"{stem}.onnx", "fp32_max_abs_error": _check(stem, _session(data).run(None, feed)[0], want)}
    if fp16:
        half = fp16_weights(model).SerializeToString()
        (folder / f"{stem}.fp16.onnx").write_bytes(half)
        entry["fp16"] = f"{stem}.fp16.onnx"
        entry["fp16_max_abs_error"] = float(np.abs(_session(half).run(None, feed)[0] - want).max())
    onnx.checker.check_model(model)
    return entry


def _text_encoder(loaded: LoadedModel, folder: Path, scratch: Path, fp16: bool) -> dict:
    """The MiniLM graph, its tokenizer files and their JSON entry."""
    import onnx

    from kinema.text import MiniLMEncoder

    if loaded.text_encoder_id != MINILM_ID:
        raise KinemaError(f"export-onnx: the model uses the text encoder {loaded.text_encoder_id!r}; only "
                          f"{MINILM_ID!r} can be exported")
    encoder = MiniLMEncoder()
    minilm, src = encoder._load(), encoder._resolve_model_dir()
    export_encoder(minilm.model, scratch / "text_encoder.onnx")
    text = "A person walks forward."
    ids = minilm.tokenizer.encode(text.lower() if minilm.lower_case else text).ids
    feed = {"input_ids": np.array([ids], dtype=np.int64), "attention_mask": np.ones((1, len(ids)), dtype=np.int64)}
    want = encoder.encode([text]).numpy()
    entry = _write_graph(onnx.load(str(scratch / "text_encoder.onnx")), folder, "text_encoder", feed, want, fp16)
    for name in ("tokenizer.json", "vocab.txt"):
        shutil.copyfile(src / name, folder / name)
    max_tokens = minilm.tokenizer.truncation["max_length"]
    return entry | {"inputs": list(ENCODER_INPUTS), "output": "sentence_embedding", "tokenizer": "tokenizer.json",
                    "vocab": "vocab.txt", "lower_case": bool(minilm.lower_case), "max_tokens": int(max_tokens),
                    "cls": "[CLS]", "sep": "[SEP]", "unk": "[UNK]", "dim": encoder.dim, "license": "Apache-2.0"}


def export_onnx(model: str | Path, out: str | Path, fp16: bool = True) -> OnnxExport:
    """Export a human model (``"default"`` or a trained model / run folder) to the folder ``out``."""
    import onnx

    path = resolve_model_path(model)
    ckpt = find_checkpoint(path)
    name = pipeline_name(read_checkpoint_info(ckpt))
    if name != "human":
        raise KinemaError(f"export-onnx: {ckpt} is a {name!r} model; only the human pipeline can be exported")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise KinemaError(f"export-onnx: --out {out} is a file, not a folder")
    loaded = load_denoiser(ckpt, precision="fp32")
    known = KnownPrompts.load(ckpt)
    out.mkdir(parents=True, exist_ok=True)
    scratch = out / ".export"
    scratch.mkdir(exist_ok=True)
    try:
        export_denoiser(loaded.denoiser, scratch / "denoiser.onnx")
        main = onnx.load(str(scratch / "denoiser.onnx"))
        feed = _probe(loaded)
        graphs = {"denoiser": _write_graph(main, out, "denoiser", feed, _torch_guided(loaded.denoiser, feed), fp16)}
        if loaded.expert is not None:
            expert = with_weights(main, loaded.expert.denoiser.state_dict())
            graphs["action_expert"] = _write_graph(expert, out, "action_expert", feed,
                                                   _torch_guided(loaded.expert.denoiser, feed), fp16)
        for entry in graphs.values():
            entry.update({"inputs": list(DENOISER_INPUTS), "output": "x0", "opset": OPSET,
                          "dynamic_axes": {"rows": "motions x branches, branch-major", "frames": "2..max_frames",
                                           "branches": "len(weights), 1..4"}})
        text = _text_encoder(loaded, out, scratch, fp16) | {"opset": OPSET}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    manifest = build_manifest(loaded, known, graphs, text, source=str(path.name if path.name else path))
    (out / FILE_NAME).write_text(json.dumps(manifest) + "\n", encoding="utf-8")
    (out / "LICENSE.txt").write_text(LICENSE + "\n", encoding="utf-8")
    size = sum(f.stat().st_size for f in out.iterdir() if f.is_file())
    return OnnxExport(out, manifest, size)
