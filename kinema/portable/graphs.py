"""The networks of the human model as ONNX graphs: the guided denoiser and the MiniLM sentence encoder.

``GuidedDenoiser`` is the whole network call of one DDIM step: every guidance branch of every motion in
one batch (branch-major, as :func:`kinema.diffusion.guidance.stack_branches` stacks them), both stages
(root, then body on the local root the root stage predicts) and the weighted sum of the branches, so a
runtime makes one ``session.run`` per step and never needs the branch arithmetic of a guidance mode:

    inputs   x_t (rows, frames, D) f32, t (rows,) i64, text_emb (rows, E) f32, c_dir (rows, 2) f32,
             x_tgt (rows, frames, D) f32, mask (rows, frames, D) f32, weights (branches,) f32
    output   x0 (rows / branches, frames, D) f32 = sum_k weights[k] * D(rows of branch k)

A runtime zeroes ``text_emb`` on the rows of a branch without text and ``mask`` on the rows of a branch
without constraints; the weights of a mode are ``regular`` [1 - w, w], ``separated`` [1 - w_t - w_c, w_t,
w_c], ``none`` [1] (docs/onnx_runtime.md). ``SentenceEncoder`` maps token ids and their attention mask
to the unit sentence embedding (mean pooling and L2 normalisation inside the graph).

Exported with torch's dynamo exporter (``torch.onnx.export(dynamo=True)``, opset :data:`OPSET`), unoptimised
so that every weight keeps its parameter's name: the action expert's graph is the main graph with the
expert's weights put in by name (:func:`with_weights`), and :func:`fp16_weights` stores weights in float16
behind Cast nodes (the arithmetic stays float32).
"""

from __future__ import annotations

import contextlib
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from kinema.errors import KinemaError
from kinema.minilm import MiniLMModel
from kinema.model.denoiser import Denoiser

#: the ONNX opset the graphs are written in (onnxruntime >= 1.14 and onnxruntime-web run it)
OPSET = 18
#: names of the denoiser graph's inputs, in order
DENOISER_INPUTS = ("x_t", "t", "text_emb", "c_dir", "x_tgt", "mask", "weights")
#: names of the text encoder graph's inputs, in order
ENCODER_INPUTS = ("input_ids", "attention_mask")
#: the prefix the wrapper gives the denoiser's parameter names inside the graph
DENOISER_PREFIX = "denoiser."
#: weights with at least this many numbers are stored in float16 by :func:`fp16_weights`
FP16_MIN_SIZE = 1024


class GuidedDenoiser(nn.Module):
    """One guided DDIM step's network call (module docstring)."""

    def __init__(self, denoiser: Denoiser):
        super().__init__()
        self.denoiser = denoiser

    def forward(self, x_t, t, text_emb, c_dir, x_tgt, mask, weights):
        out = self.denoiser(x_t, t, text_emb, None, c_dir, x_tgt, mask)
        out = out.unflatten(0, (weights.shape[0], -1))
        return (weights[:, None, None, None] * out).sum(0)


class SentenceEncoder(nn.Module):
    """MiniLM token ids ``(B, L)`` and mask ``(B, L)`` -> unit sentence embeddings ``(B, H)``."""

    def __init__(self, model: MiniLMModel):
        super().__init__()
        self.model = model

    def forward(self, input_ids, attention_mask):
        return self.model(input_ids, attention_mask)


@contextlib.contextmanager
def _exporting():
    """Settings every export runs under: no autograd, PyTorch's fused transformer fast path off (ONNX has
    no such operator) and the exporter's chatter silenced."""
    before = torch.backends.mha.get_fastpath_enabled()
    torch.backends.mha.set_fastpath_enabled(False)
    try:
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        torch.backends.mha.set_fastpath_enabled(before)


def export_graph(module: nn.Module, args: tuple, path: Path, input_names, output_name: str, dynamic: dict) -> None:
    """Write ``module`` as one ONNX file (weights inside) at ``path``; ``dynamic``: per input name the
    ``{axis: torch.export.Dim}`` of its named dynamic axes."""
    try:
        import onnxscript  # noqa: F401  (torch's dynamo exporter needs it)
    except ImportError:
        raise KinemaError("export-onnx needs the onnx extra: pip install 'kinema[onnx]'") from None
    with _exporting(), contextlib.redirect_stdout(None):
        torch.onnx.export(module.eval(), args, str(path), dynamo=True, opset_version=OPSET, optimize=False,
                          input_names=list(input_names), output_names=[output_name],
                          dynamic_shapes={n: dynamic.get(n, {}) for n in input_names}, external_data=False,
                          verbose=False)


def export_denoiser(denoiser: Denoiser, path: Path) -> None:
    """The guided denoiser graph of ``denoiser`` (module docstring) at ``path``."""
    from torch.export import Dim

    cfg = denoiser.config
    rows, frames = Dim("rows", min=1, max=4096), Dim("frames", min=2, max=cfg.max_frames)
    branches = Dim("branches", min=1, max=4)
    n, T, D = 2, min(cfg.max_frames, 64), cfg.feature_dim
    args = (torch.zeros(n, T, D), torch.full((n,), 1, dtype=torch.long), torch.zeros(n, cfg.text_dim),
            torch.zeros(n, 2), torch.zeros(n, T, D), torch.zeros(n, T, D), torch.ones(2))
    per_row = {"x_t": {0: rows, 1: frames}, "t": {0: rows}, "text_emb": {0: rows}, "c_dir": {0: rows},
               "x_tgt": {0: rows, 1: frames}, "mask": {0: rows, 1: frames}, "weights": {0: branches}}
    export_graph(GuidedDenoiser(denoiser), args, path, DENOISER_INPUTS, "x0", per_row)


def export_encoder(model: MiniLMModel, path: Path) -> None:
    """The sentence encoder graph of a MiniLM network at ``path`` (dynamic ``batch`` and ``tokens``)."""
    from torch.export import Dim

    batch, tokens = Dim("batch", min=1, max=256), Dim("tokens", min=2, max=model.cfg.max_position_embeddings)
    args = (torch.ones(2, 8, dtype=torch.long), torch.ones(2, 8, dtype=torch.long))
    dynamic = {name: {0: batch, 1: tokens} for name in ENCODER_INPUTS}
    export_graph(SentenceEncoder(model), args, path, ENCODER_INPUTS, "sentence_embedding", dynamic)


def with_weights(model, state: dict[str, torch.Tensor], prefix: str = DENOISER_PREFIX):
    """A copy of the ONNX ``model`` whose weights named ``prefix + name`` hold ``state[name]`` instead (the
    same network with other weights, e.g. the action expert's); every tensor of ``state`` must have its
    weight in the graph, with the same shape."""
    import onnx
    from onnx import numpy_helper

    out = onnx.ModelProto()
    out.CopyFrom(model)
    by_name = {init.name: init for init in out.graph.initializer}
    for name, tensor in state.items():
        init = by_name.get(prefix + name)
        if init is None or tuple(init.dims) != tuple(tensor.shape):
            raise KinemaError(f"ONNX export: the graph has no weight {prefix + name} of shape {tuple(tensor.shape)}")
        init.CopyFrom(numpy_helper.from_array(tensor.detach().float().numpy().astype(init_dtype(init)), init.name))
    return out


def init_dtype(init) -> np.dtype:
    from onnx import helper

    return np.dtype(helper.tensor_dtype_to_np_dtype(init.data_type))


def fp16_weights(model, min_size: int = FP16_MIN_SIZE):
    """A copy of the ONNX ``model`` with every float32 weight of at least ``min_size`` numbers stored in
    float16 and cast back to float32 by a Cast node in front of its users: half the file, float32
    arithmetic (runtimes without float16 kernels, such as onnxruntime-web's wasm, run it unchanged)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    out = onnx.ModelProto()
    out.CopyFrom(model)
    graph = out.graph
    kept, casts = [], []
    for init in graph.initializer:
        if init.data_type != TensorProto.FLOAT or int(np.prod(init.dims)) < min_size:
            kept.append(init)
            continue
        half = numpy_helper.from_array(numpy_helper.to_array(init).astype(np.float16), init.name + "__fp16")
        kept.append(half)
        casts.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT,
                                      name=init.name + "__cast"))
    del graph.initializer[:]
    graph.initializer.extend(kept)
    nodes = list(graph.node)
    del graph.node[:]
    graph.node.extend(casts + nodes)
    onnx.checker.check_model(out)
    return out
