"""Set-level metrics over embeddings: FID, diversity, multimodality, R-precision, coverage/novelty AUC.

Inputs are plain tensors or arrays (any retrieval model, or raw pose features): ``(N, E)`` rows are
samples; extra trailing axes are flattened. Everything is computed in float64; distances are
Euclidean unless a function says otherwise. Random choices take a ``torch.Generator`` so results are
reproducible.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import torch

from kinema.errors import KinemaError


def _rows(x, what: str, min_rows: int = 1) -> torch.Tensor:
    """(N, D) float64 tensor from a tensor/array of shape (N, ...)."""
    t = torch.as_tensor(np.asarray(x) if not isinstance(x, torch.Tensor) else x).detach().cpu().to(torch.float64)
    if t.ndim == 0:
        raise KinemaError(f"{what} must have a leading sample axis, got a scalar")
    t = t.reshape(t.shape[0], -1)
    if t.shape[0] < min_rows:
        raise KinemaError(f"{what} needs at least {min_rows} samples, got {t.shape[0]}")
    if not torch.isfinite(t).all():
        raise KinemaError(f"{what} contains NaN or inf")
    return t


# ----------------------------------------------------------------------------- FID


def _sqrtm(a: np.ndarray, accept_any: bool = False) -> np.ndarray | None:
    """``scipy.linalg.sqrtm(a)``, or None when it is not finite or ``X @ X`` misses ``a`` by > 1e-6."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        x = scipy.linalg.sqrtm(a)
    if accept_any:
        return x
    if not np.isfinite(x).all():
        return None
    err = np.linalg.norm(x @ x - a) / max(np.linalg.norm(a), 1e-300)
    return x if err < 1e-6 else None


def fid(real, fake, eps: float = 1e-6) -> float:
    """Fréchet distance between Gaussians fitted to two embedding sets (squared embedding units).

    ``FID = ||mu_r - mu_f||^2 + tr(C_r + C_f - 2 (C_r C_f)^{1/2})`` with sample means and unbiased
    covariances of ``real (N, E)`` and ``fake (M, E)``; the square root is ``scipy.linalg.sqrtm``. When
    it is not finite or inaccurate (singular covariances: ``||X X - C_r C_f|| > 1e-6 ||C_r C_f||``),
    ``eps * I`` is added to both covariances and the root is taken again. Rounding can give
    ``sqrtm`` tiny imaginary parts: the real part is kept (a warning names a large imaginary part), and
    the result is clamped at 0 (FID is >= 0 mathematically). Kimodo's tables print FID x 100.
    """
    r, f = _rows(real, "real", 2), _rows(fake, "fake", 2)
    if r.shape[1] != f.shape[1]:
        raise KinemaError(f"real and fake embeddings differ in size: {r.shape[1]} vs {f.shape[1]}")
    x, y = r.numpy(), f.numpy()
    mu1, mu2 = x.mean(0), y.mean(0)
    c1, c2 = np.atleast_2d(np.cov(x, rowvar=False)), np.atleast_2d(np.cov(y, rowvar=False))
    covmean = _sqrtm(c1 @ c2)
    if covmean is None:
        offset = np.eye(c1.shape[0]) * eps
        covmean = _sqrtm((c1 + offset) @ (c2 + offset), accept_any=True)
    if np.iscomplexobj(covmean):
        imag = np.abs(covmean.imag).max()
        if imag > 1e-3 * max(1.0, np.abs(covmean.real).max()):
            warnings.warn(f"FID: sqrtm has an imaginary part of {imag:.3g}; keeping the real part", stacklevel=2)
        covmean = covmean.real
    value = float(((mu1 - mu2) ** 2).sum() + np.trace(c1) + np.trace(c2) - 2.0 * np.trace(covmean))
    return max(value, 0.0)


# ----------------------------------------------------------------------------- diversity


def diversity(emb, pairs: int = 300, generator: torch.Generator | None = None) -> float:
    """Mean Euclidean distance between random pairs of samples (HumanML3D "Diversity").

    Two independent random subsets of ``pairs`` distinct indices ``a, b`` are drawn from the N samples
    (as in HumanML3D's evaluator), and ``div = mean_i || emb[a_i] - emb[b_i] ||``. Needs N >= pairs.
    """
    e = _rows(emb, "emb")
    if e.shape[0] < pairs:
        raise KinemaError(f"diversity with {pairs} pairs needs at least {pairs} samples, got {e.shape[0]}")
    a = torch.randperm(e.shape[0], generator=generator)[:pairs]
    b = torch.randperm(e.shape[0], generator=generator)[:pairs]
    return float((e[a] - e[b]).norm(dim=-1).mean())


def multimodality(
    emb_groups: Sequence | torch.Tensor, pairs: int = 10, generator: torch.Generator | None = None
) -> float:
    """Mean distance between samples generated from the same prompt (HumanML3D "MultiModality").

    ``emb_groups`` is a list of ``(S_i, E)`` embeddings (S_i >= 2 samples of prompt i) or a tensor
    ``(P, S, E)``. For every group, ``pairs`` random pairs ``(a, b)`` with ``a != b`` are drawn uniformly
    (with replacement between pairs, so any S_i >= 2 works) and
    ``mm = mean_{i, pairs} || emb_i[a] - emb_i[b] ||`` over all groups' pairs.
    """
    dists = []
    for n, group in enumerate(emb_groups):
        g = _rows(group, f"emb_groups[{n}]", 2)
        S = g.shape[0]
        a = torch.randint(S, (pairs,), generator=generator)
        b = torch.randint(S - 1, (pairs,), generator=generator)
        b = b + (b >= a).long()  # uniform over the other S - 1 samples
        dists.append((g[a] - g[b]).norm(dim=-1))
    if not dists:
        raise KinemaError("multimodality needs at least one group of samples")
    return float(torch.cat(dists).mean())


# ----------------------------------------------------------------------------- R-precision


def _distances(a: torch.Tensor, b: torch.Tensor, metric: str) -> torch.Tensor:
    """(..., len(a), len(b)) distances (batched): Euclidean, or ``1 - cosine similarity``."""
    if metric == "euclidean":
        return torch.cdist(a, b)
    if metric == "cosine":
        an = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        bn = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        return 1.0 - an @ bn.transpose(-1, -2)
    raise KinemaError(f"unknown metric {metric!r}; use 'cosine' or 'euclidean'")


def r_precision(
    text_emb,
    motion_emb,
    ks: Sequence[int] = (1, 3),
    batch_size: int | None = None,
    generator: torch.Generator | None = None,
    metric: str = "cosine",
) -> dict[int, float]:
    """Text retrieval accuracy R@k in [0, 1] for each k in ``ks``.

    Row i of ``text_emb (N, E)`` describes row i of ``motion_emb (N, E)``. For each motion, the
    candidate texts are ranked by distance (``metric="cosine"``: ``1 - cos``, as TMR; ``"euclidean"``:
    as HumanML3D's evaluator); ``rank_i`` = number of candidate texts strictly closer than its own text
    (exact ties, e.g. duplicate captions, count in its favour), and ``R@k = mean_i [rank_i < k]``.
    ``batch_size=None`` ranks against all N texts (Kimodo, chance ``k / N``); ``batch_size=32`` is the
    HumanML3D protocol: a random permutation split into batches of 32 (the incomplete last batch is
    dropped), ranking within each batch (chance ``k / 32``).
    """
    t, m = _rows(text_emb, "text_emb"), _rows(motion_emb, "motion_emb")
    if t.shape != m.shape:
        raise KinemaError(f"text and motion embeddings must match in shape, got {tuple(t.shape)} and {tuple(m.shape)}")
    N = t.shape[0]
    if batch_size is None:
        idx = torch.arange(N)[None]
    else:
        if N < batch_size:
            raise KinemaError(f"R-precision with batch_size={batch_size} needs at least that many samples, got {N}")
        perm = torch.randperm(N, generator=generator)
        idx = perm[: N - N % batch_size].reshape(-1, batch_size)
    d = _distances(m[idx], t[idx], metric)  # (batches, B motions, B texts)
    rank = (d < d.diagonal(dim1=-2, dim2=-1)[..., None]).sum(dim=-1).reshape(-1)
    return {int(k): float((rank < k).to(torch.float64).mean()) for k in ks}


# ----------------------------------------------------------------------------- coverage / novelty


@dataclass
class CoverageNovelty:
    """AUCs in [0, 1] and, when thresholds were given, the curves sampled at them."""

    coverage_auc: float
    novelty_auc: float
    thresholds: torch.Tensor | None = None
    coverage: torch.Tensor | None = None
    novelty: torch.Tensor | None = None


def sliding_windows(sequences, size: int) -> torch.Tensor:
    """All stride-1 windows of ``size`` frames from each ``(L_i, D)`` sequence, flattened: ``(W, size * D)``.

    Dragon eq. (8): ``W(x, F_w) = {x[i : i + F_w]}`` for ``i = 0 .. L - F_w``.
    """
    out = []
    for n, seq in enumerate(sequences):
        s = torch.as_tensor(seq).to(torch.float64)
        s = s.reshape(s.shape[0], -1)
        if s.shape[0] < size:
            raise KinemaError(f"sequence {n} has {s.shape[0]} frames, fewer than the window of {size}")
        out.append(s.unfold(0, size, 1).transpose(1, 2).reshape(-1, size * s.shape[1]))
    return torch.cat(out)


def _nearest(queries: torch.Tensor, refs: torch.Tensor, metric: str, chunk: int = 4096) -> torch.Tensor:
    """Per query: max cosine similarity (``cosine``) or min Euclidean distance (``euclidean``) to refs."""
    out = []
    for q in queries.split(chunk):
        d = _distances(q, refs, metric)
        out.append(1.0 - d.min(dim=1).values if metric == "cosine" else d.min(dim=1).values)
    return torch.cat(out)


def coverage_novelty_auc(
    generated,
    train,
    test,
    metric: str = "cosine",
    tau_max: float | None = None,
    window: int | None = None,
    thresholds=None,
) -> CoverageNovelty:
    """Coverage of the test set and novelty w.r.t. the training set, as areas under threshold sweeps.

    Mapping onto Dragon (App. C, eqs. 8-10): their reference ``x`` is the test set for coverage and the
    training set for novelty ("inverse coverage of original motions ... in the training set"); their
    per-window vectors are our rows (embeddings or pose-feature vectors; with ``window=F`` the inputs
    are lists of ``(L_i, D)`` sequences cut into stride-1 windows of ``F_w = min(F, shortest L_i)``
    frames and flattened -- Dragon takes ``min(L_x, L_x_hat, F)`` per pair of motions, we pool every
    window of a set, so one ``F_w`` serves all sets). With ``s(a, B) = max_{b in B} cos(a, b)``:

    - ``Cov(Theta) = mean_{x in test} [s(x, generated) > Theta]``            (eq. 9)
    - ``Nov(Theta) = mean_{g in generated} [1 - s(g, train) > Theta]``     (eq. 10)
    - AUC = integral over Theta in [0, 1] (their sweep from 0 to 1), computed exactly rather than on a
      grid: ``AUC_cov = mean clip(s, 0, 1)`` and ``AUC_nov = mean clip(1 - s, 0, 1)``.

    ``metric="euclidean"`` is the distance-threshold variant: with ``d(a, B) = min_b ||a - b||``,
    ``Cov(tau) = mean [d(x, generated) <= tau]``, ``Nov(tau) = mean [d(g, train) > tau]``, and AUCs
    normalised over tau in [0, tau_max]: ``mean clip(1 - d / tau_max, 0, 1)`` and
    ``mean clip(d / tau_max, 0, 1)``. ``tau_max`` defaults to the largest of these nearest distances;
    fix it explicitly when comparing models. ``thresholds`` (Theta or tau values) additionally
    returns the two curves sampled there.
    """
    if window is not None:
        lengths = [len(s) for group in (generated, train, test) for s in group]
        if not lengths:
            raise KinemaError("coverage_novelty_auc needs sequences to cut windows from")
        size = min(int(window), *lengths)
        gen, tr, te = (sliding_windows(x, size) for x in (generated, train, test))
    else:
        gen, tr, te = _rows(generated, "generated"), _rows(train, "train"), _rows(test, "test")
    if not gen.shape[1] == tr.shape[1] == te.shape[1]:
        raise KinemaError(f"feature sizes differ: generated {gen.shape[1]}, train {tr.shape[1]}, test {te.shape[1]}")
    s_test = _nearest(te, gen, metric)  # per test row: closeness of the best generated row
    s_gen = _nearest(gen, tr, metric)  # per generated row: closeness of the best training row
    thr = None if thresholds is None else torch.as_tensor(thresholds, dtype=torch.float64).reshape(-1)
    if metric == "cosine":
        cov_auc = s_test.clamp(0.0, 1.0).mean()
        nov_auc = (1.0 - s_gen).clamp(0.0, 1.0).mean()
        cov_curve = None if thr is None else (s_test[None] > thr[:, None]).double().mean(1)
        nov_curve = None if thr is None else ((1.0 - s_gen)[None] > thr[:, None]).double().mean(1)
    else:
        top = float(tau_max) if tau_max is not None else float(torch.cat([s_test, s_gen]).max())
        if top <= 0:  # every nearest distance is zero: full coverage, no novelty
            cov_auc, nov_auc = torch.tensor(1.0), torch.tensor(0.0)
        else:
            cov_auc = (1.0 - s_test / top).clamp(0.0, 1.0).mean()
            nov_auc = (s_gen / top).clamp(0.0, 1.0).mean()
        cov_curve = None if thr is None else (s_test[None] <= thr[:, None]).double().mean(1)
        nov_curve = None if thr is None else (s_gen[None] > thr[:, None]).double().mean(1)
    return CoverageNovelty(float(cov_auc), float(nov_auc), thr, cov_curve, nov_curve)
