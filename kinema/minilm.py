"""all-MiniLM-L6-v2 in plain torch + the ``tokenizers`` package, without sentence-transformers.

Why: importing sentence-transformers pulls in transformers and scikit-learn, which cost 3-4 s per
fresh process before the first prompt can be embedded. The model itself is a 6-layer BERT, so a
~100-line torch module reproduces it exactly, loads in a few hundredths of a second and needs only
``tokenizers`` (the Rust tokenizer, reading the bundled ``tokenizer.json``) and ``safetensors``.

What it computes is exactly the sentence-transformers pipeline in the model folder's
``modules.json`` (checked at load time, so a different folder fails loudly instead of silently
embedding differently):

1. ``Transformer``: BERT tokenisation truncated to ``max_seq_length`` tokens (256, from
   ``sentence_bert_config.json``, including [CLS] and [SEP]), then a post-LayerNorm BERT encoder
   (exact erf GELU, absolute positions, token type 0) -> token states ``(B, L, H)``;
2. ``Pooling``: mean over the real tokens (attention mask), ``1_Pooling/config.json``;
3. ``Normalize``: L2 normalisation of each row.

Weights are read with safetensors only (never pickle). Terms: B = batch size, L = tokens in the
longest text of the batch, H = hidden size (384), N = attention heads (12), D = H / N.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from .errors import KinemaError

__all__ = ["BertConfig", "MiniLMModel", "load_minilm"]

# The sentence-transformers module chain this implementation reproduces (modules.json "type"s).
_EXPECTED_MODULES = [
    "sentence_transformers.models.Transformer",
    "sentence_transformers.models.Pooling",
    "sentence_transformers.models.Normalize",
]


@dataclass(frozen=True)
class BertConfig:
    """The BERT hyper-parameters read from the model folder's ``config.json``."""

    vocab_size: int
    hidden_size: int
    num_hidden_layers: int
    num_attention_heads: int
    intermediate_size: int
    max_position_embeddings: int
    type_vocab_size: int
    layer_norm_eps: float

    @classmethod
    def from_file(cls, path: Path) -> BertConfig:
        """Read ``config.json``, refusing any BERT variant this module does not implement."""
        cfg = _read_json(path)
        unsupported = {
            "model_type": (cfg.get("model_type"), "bert"),
            "hidden_act": (cfg.get("hidden_act"), "gelu"),
            "position_embedding_type": (cfg.get("position_embedding_type", "absolute"), "absolute"),
        }
        for key, (got, want) in unsupported.items():
            if got != want:
                raise KinemaError(f"{path}: {key} is {got!r}; the built-in MiniLM encoder only supports {want!r}")
        try:
            out = cls(**{f: cfg[f] for f in cls.__dataclass_fields__})
        except KeyError as exc:
            raise KinemaError(f"{path}: missing BERT setting {exc}") from exc
        if out.hidden_size % out.num_attention_heads:
            raise KinemaError(f"{path}: hidden_size is not a multiple of num_attention_heads")
        return out


def _read_json(path: Path) -> dict:
    """Load one JSON config file, turning a missing or broken file into a :class:`KinemaError`."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise KinemaError(f"cannot read model config {path}: {exc}") from exc


# --------------------------------------------------------------------------------------------------
# The network
# --------------------------------------------------------------------------------------------------


class _BertLayer(nn.Module):
    """One post-LayerNorm BERT block: self-attention and a GELU feed-forward, each + residual + LN."""

    def __init__(self, cfg: BertConfig):
        super().__init__()
        h = cfg.hidden_size
        self.heads = cfg.num_attention_heads
        self.q = nn.Linear(h, h)
        self.k = nn.Linear(h, h)
        self.v = nn.Linear(h, h)
        self.attn_out = nn.Linear(h, h)
        self.attn_norm = nn.LayerNorm(h, eps=cfg.layer_norm_eps)
        self.ffn_in = nn.Linear(h, cfg.intermediate_size)
        self.ffn_out = nn.Linear(cfg.intermediate_size, h)
        self.ffn_norm = nn.LayerNorm(h, eps=cfg.layer_norm_eps)

    def forward(self, x: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
        """``x`` (B, L, H) token states, ``keep`` (B, 1, 1, L) bool, True on real tokens -> (B, L, H)."""
        b, n, h = x.shape

        def heads(t: torch.Tensor) -> torch.Tensor:  # (B, L, H) -> (B, N, L, D)
            return t.view(b, n, self.heads, h // self.heads).transpose(1, 2)

        ctx = F.scaled_dot_product_attention(heads(self.q(x)), heads(self.k(x)), heads(self.v(x)), attn_mask=keep)
        x = self.attn_norm(x + self.attn_out(ctx.transpose(1, 2).reshape(b, n, h)))
        return self.ffn_norm(x + self.ffn_out(F.gelu(self.ffn_in(x))))


def _uninitialised_embedding(num: int, dim: int) -> nn.Embedding:
    """An embedding table without random init (the checkpoint overwrites it).

    Why: ``nn.Embedding``'s ``normal_`` init on the meta device (see :func:`load_minilm`) imports
    torch._dynamo and sympy, ~1.2 s; passing ``_weight`` skips it.
    """
    return nn.Embedding(num, dim, _weight=torch.empty(num, dim))


class MiniLMModel(nn.Module):
    """BERT encoder + masked mean pooling + L2 normalisation: token ids -> unit sentence vectors."""

    def __init__(self, cfg: BertConfig):
        super().__init__()
        self.cfg = cfg
        h = cfg.hidden_size
        self.word = _uninitialised_embedding(cfg.vocab_size, h)
        self.position = _uninitialised_embedding(cfg.max_position_embeddings, h)
        self.token_type = _uninitialised_embedding(cfg.type_vocab_size, h)
        self.embed_norm = nn.LayerNorm(h, eps=cfg.layer_norm_eps)
        self.layers = nn.ModuleList(_BertLayer(cfg) for _ in range(cfg.num_hidden_layers))

    def forward(self, ids: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """``ids`` (B, L) int64 token ids, ``mask`` (B, L) 1 on real tokens / 0 on padding -> (B, H).

        Single-sentence input, so every token has type 0 (as the tokenizer's template assigns).
        """
        n = ids.shape[1]
        x = self.word(ids) + self.position.weight[:n] + self.token_type.weight[0]  # (B, L, H)
        x = self.embed_norm(x)
        keep = mask.bool()[:, None, None, :]  # (B, 1, 1, L): padded keys get no attention
        for layer in self.layers:
            x = layer(x, keep)
        m = mask.to(x.dtype).unsqueeze(-1)  # (B, L, 1)
        pooled = (x * m).sum(1) / m.sum(1).clamp(min=1e-9)  # (B, H), as sentence-transformers' Pooling
        return F.normalize(pooled, p=2, dim=1)


# Checkpoint (Hugging Face BertModel) names -> this module's names. Unlisted keys are an error.
_RENAMES = [
    ("embeddings.word_embeddings.", "word."),
    ("embeddings.position_embeddings.", "position."),
    ("embeddings.token_type_embeddings.", "token_type."),
    ("embeddings.LayerNorm.", "embed_norm."),
    ("encoder.layer.", "layers."),
    (".attention.self.query.", ".q."),
    (".attention.self.key.", ".k."),
    (".attention.self.value.", ".v."),
    (".attention.output.dense.", ".attn_out."),
    (".attention.output.LayerNorm.", ".attn_norm."),
    (".intermediate.dense.", ".ffn_in."),
    (".output.dense.", ".ffn_out."),
    (".output.LayerNorm.", ".ffn_norm."),
]
# Present in the checkpoint but unused by sentence embeddings: the CLS pooler and a constant arange.
_IGNORED_PREFIXES = ("pooler.", "embeddings.position_ids")


def _convert_state_dict(raw: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Rename BertModel weights to :class:`MiniLMModel` names (tolerating a ``bert.`` prefix)."""
    out = {}
    for key, value in raw.items():
        key = key.removeprefix("bert.")
        if key.startswith(_IGNORED_PREFIXES):
            continue
        for old, new in _RENAMES:
            key = key.replace(old, new)
        out[key] = value
    return out


# --------------------------------------------------------------------------------------------------
# Tokenizer + model bundle
# --------------------------------------------------------------------------------------------------


def _check_pipeline(path: Path) -> tuple[int, bool]:
    """Verify the folder is Transformer -> mean Pooling -> Normalize; return (max_seq_length, lower)."""
    modules = _read_json(path / "modules.json")
    types = [m.get("type") for m in sorted(modules, key=lambda m: m.get("idx", 0))]
    if types != _EXPECTED_MODULES:
        raise KinemaError(f"{path}: module chain {types} is not Transformer -> Pooling -> Normalize")
    pooling = _read_json(path / "1_Pooling" / "config.json")
    modes = sorted(k for k, v in pooling.items() if k.startswith("pooling_mode") and v)
    if modes != ["pooling_mode_mean_tokens"]:
        raise KinemaError(f"{path}: pooling modes {modes}; only mean pooling is supported")
    st_cfg = _read_json(path / "sentence_bert_config.json")
    return int(st_cfg["max_seq_length"]), bool(st_cfg.get("do_lower_case", False))


class MiniLM:
    """A loaded sentence encoder: the tokenizer and the network, both read-only after loading.

    Thread safety: :meth:`embed` mutates nothing shared. The tokenizer's truncation is configured
    once in :func:`load_minilm` and never changed (changing it while another thread encodes is what
    raises "Already borrowed" in ``tokenizers``); texts are encoded one at a time with
    ``Tokenizer.encode`` rather than ``encode_batch``, so no Rust thread pool is started (which would
    make ``tokenizers`` warn and disable itself when the process later forks, e.g. DataLoader workers).
    The network runs in eval mode under ``no_grad`` and holds no state between calls.
    """

    def __init__(self, tokenizer, model: MiniLMModel, lower_case: bool, device: torch.device):
        self.tokenizer = tokenizer
        self.model = model
        self.lower_case = lower_case
        self.device = device

    def embed(self, texts: list[str], batch_size: int = 64) -> torch.Tensor:
        """Embed ``texts`` as a ``(B, H)`` float32 CPU tensor of unit rows, in input order.

        Texts are batched longest first (as sentence-transformers does) so little padding is computed.
        """
        ids = [self.tokenizer.encode(t.lower() if self.lower_case else t).ids for t in texts]
        order = sorted(range(len(ids)), key=lambda i: -len(ids[i]))
        out = torch.empty((len(ids), self.model.cfg.hidden_size), dtype=torch.float32)
        with torch.no_grad():
            for start in range(0, len(order), batch_size):
                rows = order[start : start + batch_size]
                tok, mask = _pad([ids[i] for i in rows])
                vec = self.model(tok.to(self.device), mask.to(self.device))
                out[rows] = vec.to("cpu", torch.float32)
        return out


def _pad(seqs: list[list[int]]) -> tuple[torch.Tensor, torch.Tensor]:
    """Right-pad token id lists with 0 ([PAD]) -> ids (B, L) int64 and mask (B, L) int64."""
    n = max(len(s) for s in seqs)
    ids = torch.zeros((len(seqs), n), dtype=torch.long)
    mask = torch.zeros((len(seqs), n), dtype=torch.long)
    for i, s in enumerate(seqs):
        ids[i, : len(s)] = torch.tensor(s, dtype=torch.long)
        mask[i, : len(s)] = 1
    return ids, mask


def load_minilm(path: str | Path, device: str | torch.device = "cpu") -> MiniLM:
    """Load a sentence-transformers BERT folder (all-MiniLM-L6-v2) from ``path``, offline.

    Reads ``tokenizer.json`` with ``tokenizers``, ``config.json`` and ``model.safetensors`` with
    safetensors (a folder holding only a pickled ``pytorch_model.bin`` is refused). The network is
    built on the meta device and the file's tensors are assigned in place, so no random
    initialisation runs and the weights are not copied twice.
    """
    from safetensors.torch import load_file
    from tokenizers import Tokenizer

    path = Path(path)
    max_len, lower_case = _check_pipeline(path)
    cfg = BertConfig.from_file(path / "config.json")
    weights = path / "model.safetensors"
    if not weights.is_file():
        raise KinemaError(f"{weights} not found; only safetensors weights are loaded (never pickle)")
    tokenizer = Tokenizer.from_file(str(path / "tokenizer.json"))
    tokenizer.no_padding()  # padding is done per batch in MiniLM.embed
    tokenizer.enable_truncation(max_length=min(max_len, cfg.max_position_embeddings))
    with torch.device("meta"):
        model = MiniLMModel(cfg)
    try:
        model.load_state_dict(_convert_state_dict(load_file(str(weights))), strict=True, assign=True)
    except RuntimeError as exc:
        raise KinemaError(f"{weights} does not match the MiniLM/BERT layout: {exc}") from exc
    device = torch.device(device)
    model = model.to(device).eval().requires_grad_(False)
    return MiniLM(tokenizer, model, lower_case, device)
