"""Train the retrieval model (symmetric InfoNCE) and measure its text<->motion retrieval accuracy.

**Duplicate captions.** Clips with the same content and style (and side, for mirrored copies) share
one set of captions, so a batch can hold several clips whose texts are interchangeable. Treating
them as negatives of each other would punish the model for the right answer. Like TMR's filtering of
near-duplicate negatives, but exact: the clips' *caption sets* define groups, and for each query the
other members of its group are removed from the softmax denominator (they are neither positives nor
negatives). Batches are also drawn group-first -- distinct groups, then one random clip of each -- so
each batch holds as many different descriptions as possible and rare motions are seen as often as
the many-take ones. (A text-embedding similarity threshold, as in TMR, would be wrong here: "walks
happily" and "walks wearily" are near-identical sentences that must still be told apart.)

**Evaluation** (:func:`evaluate_retrieval`) follows Kimodo Sec. 6.1 -- each clip's *first* caption
against every clip of the split -- and the HumanML3D protocol -- random batches of 32. Each is
reported two ways: *strict* (only the clip's own caption / motion is a hit) and *label-aware* (any
clip or caption with the same caption text is a hit; several test clips are takes of the same
content+style and share their captions, so strict scores are capped below 100 %). Ties are broken at
random in expectation. Chance levels are exact expectations for a random ranking.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import torch
import torch.nn.functional as F

from kinema.data.dataset import MotionDataset
from kinema.errors import KinemaError
from kinema.evaluate.retrieval import RetrievalConfig, RetrievalModel, pad_clips
from kinema.text import get_text_encoder
from kinema.train.batching import step_generator
from kinema.train.optim import lr_at

KS = (1, 3, 10)


def contrastive_loss(
    motion: torch.Tensor, text: torch.Tensor, groups: torch.Tensor, temperature: float
) -> torch.Tensor:
    """Symmetric InfoNCE over (B, E) unit embeddings; same-``groups`` pairs other than i<->i are masked."""
    logits = motion @ text.T / temperature
    same = groups[:, None] == groups[None, :]
    same.fill_diagonal_(False)
    logits = logits.masked_fill(same, float("-inf"))
    target = torch.arange(len(groups))
    return 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))


class _Sampler:
    """Group-first batches of random 2-10 s crops; a pure function of (seed, step)."""

    def __init__(
        self,
        clips: list[torch.Tensor],
        groups: list[int],
        caption_ids: list[list[int]],
        min_frames: int,
        max_frames: int,
    ):
        self.clips, self.caption_ids = clips, caption_ids
        self.groups = torch.tensor(groups)
        self.members: list[list[int]] = [[] for _ in range(int(self.groups.max()) + 1)]
        for i, g in enumerate(groups):
            self.members[g].append(i)
        self.min_frames, self.max_frames = min_frames, max_frames

    def sample(self, batch_size: int, g: torch.Generator):
        n = len(self.members)
        picks = torch.randperm(n, generator=g)[:batch_size].tolist()
        if batch_size > n:  # fewer groups than the batch: fill up with repeats
            picks += torch.randint(n, (batch_size - n,), generator=g).tolist()
        crops, captions, clip_idx = [], [], []
        for grp in picks:
            members = self.members[grp]
            i = members[int(torch.randint(len(members), (1,), generator=g))]
            clip = self.clips[i]
            T = clip.shape[0]
            lo, hi = min(T, self.min_frames), min(T, self.max_frames)
            L = int(torch.randint(lo, hi + 1, (1,), generator=g))
            start = int(torch.randint(0, T - L + 1, (1,), generator=g))
            crops.append(clip[start : start + L])
            ids = self.caption_ids[i]
            captions.append(ids[int(torch.randint(len(ids), (1,), generator=g))])
            clip_idx.append(i)
        feats, lengths = pad_clips(crops)
        return feats, lengths, torch.tensor(captions), self.groups[clip_idx]


def _caption_tables(records: list[dict]) -> tuple[list[str], list[list[int]], list[int]]:
    """Unique caption texts, each clip's caption indices into them, and each clip's caption-set group."""
    texts: dict[str, int] = {}
    sets: dict[tuple[str, ...], int] = {}
    ids, groups = [], []
    for r in records:
        caps = list(r["captions"])
        if not caps:
            raise KinemaError(f"clip {r['clip_id']} has no captions")
        ids.append([texts.setdefault(c, len(texts)) for c in caps])
        groups.append(sets.setdefault(tuple(sorted(caps)), len(sets)))
    return list(texts), ids, groups


def train_retrieval(
    data_dir: str | Path,
    out_dir: str | Path,
    steps: int = 3000,
    batch_size: int = 128,
    lr: float = 5e-4,
    seed: int = 0,
    text_encoder: str = "minilm-l6-v2",
    *,
    config: RetrievalConfig | None = None,
    cache_dir: str | Path | None = None,
    warmup: int = 100,
    weight_decay: float = 0.01,
    half: bool = False,
    progress: bool = True,
    log_every: int = 50,
    max_seconds: float | None = None,
    command: str | None = None,
) -> RetrievalModel:
    """Train on the ``train`` split of a build and save the model into ``out_dir``; returns the model.

    Deterministic for a seed (batches come from :func:`step_generator`, dropout from a seeded global
    RNG) on a given machine and thread count. ``half`` stores float16 weights. ``max_seconds`` is a safety
    stop: training ends early (keeping the schedule planned for ``steps``) once it has run that long.
    The config's ``info`` records the settings, steps done, wall time and the loss curve (mean loss
    per ``log_every`` steps)."""
    if steps < 1 or batch_size < 2:
        raise KinemaError(f"need steps >= 1 and batch_size >= 2, got {steps} and {batch_size}")
    ds, model, sampler, text_table = _setup(data_dir, text_encoder, cache_dir, config, seed)
    schedule = {"seed": seed, "steps": steps, "batch_size": batch_size, "lr": lr, "warmup": warmup}
    curve, done, wall = _fit(
        model,
        sampler,
        text_table,
        _optimizer(model, lr, weight_decay),
        schedule,
        log_every=log_every,
        max_seconds=max_seconds,
        progress=progress,
    )
    model.eval()
    model.info = {
        "data": str(data_dir),
        "train_clips": len(ds),
        "caption_groups": len(sampler.members),
        "steps": steps,
        "steps_done": done,
        "batch_size": batch_size,
        "lr": lr,
        "warmup": warmup,
        "weight_decay": weight_decay,
        "seed": seed,
        "torch_threads": torch.get_num_threads(),
        "wall_seconds": round(wall, 1),
        "loss_curve": curve,
        "command": command,
    }
    model.save(out_dir, half=half)
    return model


def _setup(
    data_dir: str | Path, text_encoder: str, cache_dir: str | Path | None, config: RetrievalConfig | None, seed: int
) -> tuple[MotionDataset, RetrievalModel, _Sampler, torch.Tensor]:
    """The train split, a freshly seeded model, its batch sampler and the caption embeddings (C, E)."""
    ds = MotionDataset(data_dir, "train")
    if len(ds) < 2:
        raise KinemaError(f"{data_dir}: the train split has {len(ds)} clips; retrieval training needs >= 2")
    encoder = get_text_encoder(text_encoder, cache_dir=cache_dir)
    texts, caption_ids, groups = _caption_tables(ds.clips)
    text_table = encoder.encode(texts).float()
    cfg = RetrievalConfig.from_dict(asdict(config or RetrievalConfig()) | {"text_dim": encoder.dim})
    torch.manual_seed(seed)
    model = RetrievalModel(cfg, ds.layout, ds.stats, ds.fps, encoder.id)
    clips = [ds[i]["features"] for i in range(len(ds))]
    sampler = _Sampler(clips, groups, caption_ids, cfg.min_frames, cfg.max_frames)
    return ds, model, sampler, text_table


def _optimizer(model: RetrievalModel, lr: float, weight_decay: float) -> torch.optim.AdamW:
    """AdamW with weight decay on matrices only (not on biases, norms or the ``cls`` token)."""
    decay = [p for n, p in model.named_parameters() if p.ndim >= 2 and n != "cls"]
    other = [p for n, p in model.named_parameters() if not (p.ndim >= 2 and n != "cls")]
    return torch.optim.AdamW(
        [{"params": decay, "weight_decay": weight_decay}, {"params": other, "weight_decay": 0.0}],
        lr=lr,
        betas=(0.9, 0.98),
    )


def _fit(
    model: RetrievalModel,
    sampler: _Sampler,
    text_table: torch.Tensor,
    opt: torch.optim.Optimizer,
    schedule: dict,
    *,
    log_every: int,
    max_seconds: float | None,
    progress: bool,
) -> tuple[list[list], int, float]:
    """The training loop: ``(loss curve [[step, mean loss]], steps done, wall seconds)``; ``schedule``
    holds seed, steps, batch_size, lr and warmup. Stops early once ``max_seconds`` have passed."""
    from tqdm.auto import tqdm

    seed, steps, batch_size = schedule["seed"], schedule["steps"], schedule["batch_size"]
    model.train()
    curve, window, t0, done = [], [], time.time(), 0
    bar = tqdm(range(steps), desc="retrieval", disable=not progress, dynamic_ncols=True)
    for step in bar:
        g = step_generator(seed, 0, step)
        feats, lengths, cap, grp = sampler.sample(batch_size, g)
        loss = contrastive_loss(
            model.encode_motion(feats, lengths), model.encode_text(text_table[cap]), grp, model.config.temperature
        )
        for group in opt.param_groups:
            group["lr"] = lr_at(step, schedule["lr"], schedule["warmup"], steps)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        window.append(float(loss.detach()))
        done = step + 1
        out_of_time = max_seconds is not None and time.time() - t0 > max_seconds
        if len(window) == log_every or done == steps or out_of_time:
            curve.append([done, round(sum(window) / len(window), 4)])
            window = []
            bar.set_postfix(loss=f"{curve[-1][1]:.3f}")
        if out_of_time:
            break
    bar.close()
    return curve, done, time.time() - t0


# ---------------------------------------------------------------------------------------------- metrics
def _hit_prob(better: torch.Tensor, ties: torch.Tensor, k: int) -> torch.Tensor:
    """P(target within the top k) when ``better`` candidates beat it and ``ties`` equal it (random order)."""
    return ((k - better.float()) / (ties.float() + 1)).clamp(0, 1)


def _recalls(sim: torch.Tensor, labels: torch.Tensor, ks=KS) -> dict:
    """R@k of each row query against the column candidates, for target i<->i: strict and label-aware."""
    N = sim.shape[0]
    eye = torch.eye(N, dtype=torch.bool)
    pos = labels[:, None] == labels[None, :]
    target = sim.diagonal()[:, None]
    better, ties = ((sim > target) & ~eye).sum(1), ((sim == target) & ~eye).sum(1)
    best_pos = sim.masked_fill(~pos, float("-inf")).max(1).values[:, None]
    better_la, ties_la = ((sim > best_pos) & ~pos).sum(1), ((sim == best_pos) & ~pos).sum(1)
    return {
        "strict": {f"R@{k}": float(_hit_prob(better, ties, k).mean()) for k in ks},
        "label_aware": {f"R@{k}": float(_hit_prob(better_la, ties_la, k).mean()) for k in ks},
    }


def _chance(labels: torch.Tensor, ks=KS) -> dict:
    """Expected R@k of a random ranking: k/N strict; 1 - C(N-m, k)/C(N, k) label-aware (m same-label)."""
    N = len(labels)
    m = (labels[:, None] == labels[None, :]).sum(1).tolist()
    out = {"strict": {f"R@{k}": min(k, N) / N for k in ks}, "label_aware": {}}
    for k in ks:
        kk = min(k, N)
        out["label_aware"][f"R@{k}"] = sum(1 - math.comb(N - mi, kk) / math.comb(N, kk) for mi in m) / N
    return out


def _ceiling(labels: torch.Tensor, ks=KS) -> dict:
    """Best possible strict R@k: a caption shared by m clips cannot single one out, so min(1, k/m)."""
    m = (labels[:, None] == labels[None, :]).sum(1).float()
    return {f"R@{k}": float((k / m).clamp(max=1).mean()) for k in ks}


def retrieval_metrics(motion: torch.Tensor, text: torch.Tensor, labels: torch.Tensor, ks=KS) -> dict:
    """Text->motion and motion->text R@k (strict and label-aware) of paired (N, E) embeddings, plus
    chance and, for strict, the ceiling that duplicate captions impose."""
    sim = text @ motion.T
    t2m, m2t = _recalls(sim, labels, ks), _recalls(sim.T.contiguous(), labels, ks)
    chance = _chance(labels, ks)
    out = {kind: {"t2m": t2m[kind], "m2t": m2t[kind], "chance": chance[kind]} for kind in ("strict", "label_aware")}
    out["strict"]["ceiling"] = _ceiling(labels, ks)
    return out


def _mean_dicts(ds: list[dict]) -> dict:
    if isinstance(ds[0], dict):
        return {k: _mean_dicts([d[k] for d in ds]) for k in ds[0]}
    return sum(ds) / len(ds)


def evaluate_retrieval(
    model: RetrievalModel,
    data_dir: str | Path,
    split: str = "test",
    *,
    cache_dir: str | Path | None = None,
    batch: int = 32,
    seed: int = 0,
) -> dict:
    """Retrieval accuracy of ``model`` on ground-truth clips of ``split`` (see the module docstring).

    Returns ``{"split", "clips", "unique_captions", "full": ..., "batch32": ...}`` where each protocol
    maps ``strict`` / ``label_aware`` to ``t2m``, ``m2t`` and ``chance`` dicts of R@1/R@3/R@10 in [0, 1].
    The batch protocol shuffles the clips with ``seed`` and averages over full batches of ``batch``."""
    ds = MotionDataset(data_dir, split)
    if len(ds) < 2:
        raise KinemaError(f"{data_dir}: split {split!r} has {len(ds)} clips; need >= 2")
    if ds.layout.to_dict() != model.layout.to_dict() or abs(ds.fps - model.fps) > 1e-6:
        raise KinemaError(f"{data_dir}: layout/fps ({ds.fps:g}) differ from the retrieval model's ({model.fps:g})")
    captions = [r["captions"][0] for r in ds.clips]
    ids: dict[str, int] = {}
    labels = torch.tensor([ids.setdefault(c, len(ids)) for c in captions])
    motion = model.encode_clips([ds[i]["features"] for i in range(len(ds))])
    text = model.encode_captions(captions, cache_dir=cache_dir)
    out = {
        "split": split,
        "clips": len(ds),
        "unique_captions": len(ids),
        "full": retrieval_metrics(motion, text, labels),
    }
    if len(ds) >= batch:
        perm = torch.randperm(len(ds), generator=torch.Generator().manual_seed(seed))
        parts = [perm[k : k + batch] for k in range(0, len(ds) - batch + 1, batch)]
        out[f"batch{batch}"] = _mean_dicts([retrieval_metrics(motion[p], text[p], labels[p]) for p in parts])
        out[f"batch{batch}"]["batches"] = len(parts)
    return out


def format_metrics(res: dict) -> str:
    """A Markdown table of an :func:`evaluate_retrieval` result (percentages)."""
    ks = [k for k in res["full"]["strict"]["t2m"]]
    head = "| protocol | variant | direction | " + " | ".join(ks) + " |"
    lines = [head, "|" + "---|" * (3 + len(ks))]
    for proto in [p for p in res if p == "full" or p.startswith("batch")]:
        name = (
            f"whole {res['split']} split ({res['clips']} clips)"
            if proto == "full"
            else f"batches of {proto[5:]} ({res[proto]['batches']} batches)"
        )
        for kind in ("strict", "label_aware"):
            for d, dname in (
                ("t2m", "text->motion"),
                ("m2t", "motion->text"),
                ("ceiling", "best possible"),
                ("chance", "chance"),
            ):
                if d not in res[proto][kind]:
                    continue
                vals = " | ".join(f"{100 * res[proto][kind][d][k]:.1f}" for k in ks)
                lines.append(f"| {name} | {kind.replace('_', '-')} | {dname} | {vals} |")
    return "\n".join(lines)


def save_metrics(res: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
