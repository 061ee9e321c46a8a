"""Prompts in other words (issue 18): does the model follow words it never saw with motion?

The training captions (kinema.data.captions templates plus kinema.data.phrasings extra and speed
captions) use a fixed set of verb phrases. This part of ``kinema evaluate`` scores the model on
phrasings that never occur in them (tests/test_phrasings.py), in two ways, on the raw model output
(no post-processing: the words must move the model, not the clean-up):

- **probes** (:data:`kinema.data.phrasings.PROBES`): each prompt is generated ``samples`` times for
  :data:`PROBE_SECONDS` and measured. Speed probes: mean ground speed of the pelvis (m/s; horizontal
  start-to-end distance over the duration, the measure the data build uses to pick speed words);
  the groups "1 slow walk" < "2 walk" < "3 jog" < "4 sprint" must come out in that order. Hand
  probes: the highest the named hand gets over the head (metres, hand joint minus head joint, Y up)
  and the same for the other hand; a sample *raises* the named hand when it gets above the head and
  higher than the other hand. The captured test clips are measured the same way for reference
  (walk / run / dash speeds, raise-up-left/right-hand clips).
- **held-out text cases**: every text case of the suite (prompt = the clip's template caption, its
  ``captions[0]``) is generated again, same seed and length, from a held-out caption of the clip's
  content label (:func:`kinema.data.phrasings.heldout_captions`). The retrieval model ranks both
  sets of motions against the template captions (R@1 / R@3 over all text cases, as the main table)
  and against the held-out captions, and FID compares each with the ground-truth clips.

Frames are at the model's fps; positions in metres.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable

import torch

from kinema.data.dataset import MotionDataset
from kinema.data.phrasings import PROBES, Probe, heldout_captions
from kinema.evaluate import distribution as D
from kinema.evaluate.probe_expectations import follows_captures, probe_expectations
from kinema.evaluate.probe_measures import (
    SHORT_SPEED_SECONDS,
    follows_side,
    ground_speed,
    group_step,
    hand_heights,
    raises_hand,
    window_speed,
)
from kinema.motion.core import Motion
from kinema.representation.kimodo_features import features_to_motion

PROBE_SECONDS = 4.0
SPEED_CONTENTS = ("walk", "run", "dash")
HAND_CONTENTS = {"left": "raise-up-left-hand", "right": "raise-up-right-hand"}
PROBE_ROLES = ("pelvis", "head", "left_hand", "right_hand")  # skeleton roles the measures need
PROBE_SEED = 70001  # probe k is generated with seed * 100003 + PROBE_SEED + k
SEPARATION = 2.0  # a speed group is faster than the one before when its mean is this many standard errors above


# ----------------------------------------------------------------------------- probes
def run_probes(
    model,
    probes: tuple[Probe, ...] = PROBES,
    *,
    samples: int,
    seed: int,
    steps=None,
    guidance=None,
    on_probe: Callable[[], None] | None = None,
) -> list[dict]:
    """Generate and measure every probe ``samples`` times (one batch per probe; raw output); speed probes
    also at :data:`SHORT_SPEED_SECONDS` (``speeds_short``, seed offset by ``len(probes)``)."""
    out = []
    for k, probe in enumerate(probes):
        kw = {"samples": samples, "steps": steps, "guidance": guidance, "postprocess": False}
        res = model.generate(probe.prompt, seconds=PROBE_SECONDS, seed=seed * 100003 + PROBE_SEED + k, **kw)
        rec = {
            "prompt": probe.prompt,
            "kind": probe.kind,
            "group": probe.group,
            "speeds": [ground_speed(m) for m in res],
            "unknown_warning": bool(getattr(getattr(res, "report", None), "warnings", None)),
        }
        if probe.kind == "speed":
            short = model.generate(
                probe.prompt, seconds=SHORT_SPEED_SECONDS, seed=seed * 100003 + PROBE_SEED + len(probes) + k, **kw
            )
            rec["speeds_short"] = [ground_speed(m) for m in short]
        if probe.kind == "hand":
            heights = [hand_heights(m, probe.group) for m in res]
            rec.update(
                hand_over_head=[h for h, _ in heights],
                other_over_head=[o for _, o in heights],
                raised=[raises_hand(h, o) for h, o in heights],
                side_followed=[follows_side(h, o) for h, o in heights],
            )
        out.append(rec)
        if on_probe is not None:
            on_probe()
    return out


def _stats(values: list[float]) -> dict:
    v = torch.tensor(values, dtype=torch.float64)
    return {
        "n": len(values),
        "mean": float(v.mean()),
        "std": float(v.std(unbiased=False)),
        "min": float(v.min()),
        "max": float(v.max()),
    }


def speed_groups(records: list[dict], key: str = "speeds") -> tuple[dict, bool | None]:
    """Speed groups of the speed records' ``key`` samples (ordered by name: mean, std, min, max; from the
    second on ``gap``, the mean minus the previous group's, its standard error ``gap_se`` and
    ``separated``: gap > :data:`SEPARATION` standard errors), and whether every group is separated from
    the one before (None for fewer than two groups)."""
    recs = [r for r in records if r["kind"] == "speed" and key in r]
    groups = sorted({r["group"] for r in recs})
    speed = {
        g: _stats([s for r in recs if r["group"] == g for s in r[key]]) | {"probes": sum(r["group"] == g for r in recs)}
        for g in groups
    }
    for prev, g in zip(groups, groups[1:], strict=False):
        gap, se, separated = group_step(speed[prev], speed[g], SEPARATION)
        speed[g].update(gap=gap, gap_se=se, separated=separated)
    return speed, None if len(groups) < 2 else all(speed[g]["separated"] for g in groups[1:])


def probe_summary(records: list[dict]) -> dict:
    """Speed groups at :data:`PROBE_SECONDS` (``speed``, ``speed_ordered``) and at
    :data:`SHORT_SPEED_SECONDS` (``speed_short``, ``speed_short_ordered``; see :func:`speed_groups`), and
    per hand probe the fraction of samples that raise the named hand."""
    speed, ordered = speed_groups(records)
    short, short_ordered = speed_groups(records, "speeds_short")
    hands = [
        {
            "prompt": r["prompt"],
            "hand": r["group"],
            "samples": len(r["raised"]),
            "raised_fraction": sum(r["raised"]) / len(r["raised"]),
            "side_fraction": sum(r["side_followed"]) / len(r["side_followed"]),
            "hand_over_head_m": _stats(r["hand_over_head"])["mean"],
            "other_over_head_m": _stats(r["other_over_head"])["mean"],
        }
        for r in records
        if r["kind"] == "hand"
    ]
    return {
        "speed": speed,
        "speed_ordered": ordered,
        "speed_short": short,
        "speed_short_ordered": short_ordered,
        "hand": hands,
    }


def captured_reference(dataset) -> dict:
    """The split's captured clips measured as the probes are: ground speed of every walk / run / dash
    clip (``speed``) and of its :data:`SHORT_SPEED_SECONDS` windows (``window_speed``, clips at least that
    long), and the fraction of raise-up-left/right-hand clips that raise the named hand."""
    speeds: dict[str, list[float]] = {c: [] for c in SPEED_CONTENTS}
    windows: dict[str, list[float]] = {c: [] for c in SPEED_CONTENTS}
    raised: dict[str, list[bool]] = {s: [] for s in HAND_CONTENTS}
    sides: dict[str, list[bool]] = {s: [] for s in HAND_CONTENTS}
    for i, rec in enumerate(dataset.clips):
        side = next((s for s, c in HAND_CONTENTS.items() if c == rec["content"]), None)
        if rec["content"] not in speeds and side is None:
            continue
        m = features_to_motion(dataset[i]["features"].double(), dataset.skeleton, dataset.fps)
        if side is None:
            speeds[rec["content"]].append(ground_speed(m))
            w = window_speed(m)
            if w is not None:
                windows[rec["content"]].append(w)
        else:
            heights = hand_heights(m, side)
            raised[side].append(raises_hand(*heights))
            sides[side].append(follows_side(*heights))
    return {
        "speed": {c: _stats(v) for c, v in speeds.items() if v},
        "window_speed": {c: _stats(v) for c, v in windows.items() if v},
        "hand": {
            s: {"clips": len(v), "raised_fraction": sum(v) / len(v), "side_fraction": sum(sides[s]) / len(v)}
            for s, v in raised.items()
            if v
        },
    }


# ----------------------------------------------------------------------------- held-out text cases
def case_content(case: dict, dataset) -> str:
    """The content label of a case's clip (mirrored clips carry the mirrored label already)."""
    return next(r["content"] for r in dataset.clips if r["clip_id"] == case["clip_id"])


def heldout_prompt(case: dict, dataset, index: int) -> str:
    """A held-out caption for a text case: of its clip's content label, the ``index``-th one cyclically."""
    caps = heldout_captions(case_content(case, dataset))
    return caps[index % len(caps)]


def content_accuracy(
    motion_emb: torch.Tensor, gt_emb: torch.Tensor, contents: list[str], leave_out_self: bool
) -> float:
    """Share of motions whose nearest ground-truth clip (cosine, retrieval motion embeddings) has their
    content label: content following judged without captions, so without style words or paraphrases.
    ``leave_out_self`` (for the ground truth itself) skips a clip's own embedding."""
    m = torch.nn.functional.normalize(motion_emb.double(), dim=-1)
    g = torch.nn.functional.normalize(gt_emb.double(), dim=-1)
    sim = m @ g.T
    if leave_out_self:
        sim.fill_diagonal_(-math.inf)
    nearest = sim.argmax(dim=-1).tolist()
    return sum(contents[j] == contents[i] for i, j in enumerate(nearest)) / len(contents)


def heldout_retrieval(
    retrieval,
    template: list[str],
    heldout: list[str],
    motions: dict[str, list[Motion]],
    embed,
    text_cache=None,
    warn: list[str] | None = None,
    contents: list[str] | None = None,
) -> dict:
    """Per row of ``motions`` ("ground_truth", "template", "heldout"): R@1 / R@3 against the template
    captions and against the held-out captions (ranked over all text cases), and FID against the
    ground truth (None for fewer than 2 cases), ``content_acc`` (:func:`content_accuracy`, given the
    cases' ``contents``; None for fewer than 2 cases); ``ranks``: per row and case, how many template
    captions are nearer to the motion than its own (0 = retrieved first; R@k = share of ranks < k)."""
    out: dict = {
        "distinct_template": len(set(template)),
        "distinct_heldout": len(set(heldout)),
        "rows": {},
        "ranks": {},
    }
    with torch.no_grad():
        texts = {
            "template": retrieval.encode_captions(template, cache_dir=text_cache),
            "heldout": retrieval.encode_captions(heldout, cache_dir=text_cache),
        }
        emb = {row: embed(retrieval, ms) for row, ms in motions.items()}
    for row, e in emb.items():
        vals = {}
        for name, t in texts.items():
            r = D.r_precision(t, e, ks=(1, 3))
            vals[f"r1_{name}"], vals[f"r3_{name}"] = r[1], r[3]
        vals["fid"] = None
        if len(template) >= 2:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                vals["fid"] = D.fid(emb["ground_truth"], e)
            if warn is not None:
                warn += [f"FID (phrasings, {row}): {w.message}" for w in caught]
        vals["content_acc"] = None
        if contents is not None and len(contents) >= 2:
            vals["content_acc"] = content_accuracy(e, emb["ground_truth"], contents, row == "ground_truth")
        out["rows"][row] = vals
        out["ranks"][row] = own_caption_ranks(texts["template"], e)
    return out


def own_caption_ranks(text_emb: torch.Tensor, motion_emb: torch.Tensor) -> list[int]:
    """Per motion i: the captions strictly nearer (cosine) than caption i, as R-precision counts them."""
    t = torch.nn.functional.normalize(text_emb.double(), dim=-1)
    m = torch.nn.functional.normalize(motion_emb.double(), dim=-1)
    d = 1.0 - m @ t.T
    return [int(r) for r in (d < d.diagonal()[:, None]).sum(dim=-1)]


def generate_heldout(
    model,
    cases: list[dict],
    motions: dict,
    datasets: dict,
    *,
    seed: int,
    steps=None,
    guidance=None,
    on_case: Callable[[], None] | None = None,
) -> tuple[list[dict], dict[str, list[Motion]]]:
    """Every text case generated again from a held-out caption (same seed and length as the case; raw).

    Returns (per case ``{"id", "prompt", "heldout_prompt"}``, rows ``ground_truth`` / ``template`` /
    ``heldout`` -> motions); ``template`` (the case's raw motion) is left out when the run had no raw row."""
    pairs, rows = [], {"ground_truth": [], "template": [], "heldout": []}
    text = [(i, c) for i, c in enumerate(cases) if c["kind"] == "text"]
    for n, (i, case) in enumerate(text):
        prompt = heldout_prompt(case, datasets[(case["source"]["data"], case["source"]["split"])], n)
        res = model.generate(
            prompt,
            seconds=case["seconds"],
            samples=1,
            steps=steps,
            guidance=guidance,
            seed=seed * 100003 + i,
            postprocess=False,
            heading=case["heading"],
        )
        content = case_content(case, datasets[(case["source"]["data"], case["source"]["split"])])
        pairs.append({"id": case["id"], "content": content, "prompt": case["prompt"], "heldout_prompt": prompt})
        rows["ground_truth"].append(motions[case["id"]]["ground_truth"])
        rows["template"].append(motions[case["id"]].get("raw"))
        rows["heldout"].append(res[0])
        if on_case is not None:
            on_case()
    if any(m is None for m in rows["template"]):
        del rows["template"]
    return pairs, rows


# ----------------------------------------------------------------------------- the part of the run
def _expected(model, probes: list[dict], samples: int, datasets: dict, data) -> dict | None:
    """kinema.evaluate.probe_expectations on the data's train split (what the model learned from)."""
    lengths = {"speed": PROBE_SECONDS, "speed_short": SHORT_SPEED_SECONDS}
    known, encoder = getattr(model, "known_prompts", None), getattr(model, "text_encoder", None)
    if known is None or encoder is None:
        return None
    if (data, "train") not in datasets:
        datasets[(data, "train")] = MotionDataset(data, "train")
    return probe_expectations(probes, known, encoder.encode, datasets[(data, "train")], samples, SEPARATION, lengths)


def run_phrasings(
    model,
    cases: list[dict],
    motions: dict,
    datasets: dict,
    retrieval,
    *,
    samples: int,
    seed: int,
    steps=None,
    guidance=None,
    text_cache=None,
    embed=None,
    warn: list[str],
    progress: bool = False,
) -> dict:
    """Probes and held-out text cases of a suite run (see the module doc); the report's ``phrasings``.

    ``motions``: the runner's case id -> {row: Motion} (the text cases' ground truth and raw motions);
    ``datasets``: (data, split) -> open MotionDataset; ``retrieval``: loaded model or None (then the
    held-out rows have no R@k); ``embed(retrieval, motions)``: retrieval embeddings (the runner's)."""
    from tqdm.auto import tqdm

    n_text = sum(c["kind"] == "text" for c in cases)
    bar = tqdm(total=len(PROBES) + n_text, desc="phrasings", disable=not progress, unit="gen")
    probes = run_probes(
        model, PROBES, samples=samples, seed=seed, steps=steps, guidance=guidance, on_probe=lambda: bar.update(1)
    )
    out = _probe_report(model, probes, samples, datasets, cases[0]["source"])
    pairs, rows = generate_heldout(
        model, cases, motions, datasets, seed=seed, steps=steps, guidance=guidance, on_case=lambda: bar.update(1)
    )
    bar.close()
    if pairs:
        out["heldout"] = _heldout_report(pairs, rows, retrieval, embed, text_cache, warn)
    return out


def _probe_report(model, probes: list, samples: int, datasets: dict, src: dict) -> dict:
    """The probes' part of the ``phrasings`` report: rows, summary, the captured reference and what the
    captions lead to expect (speeds checked against it); ``heldout`` None until the held-out cases run."""
    out = {
        "samples": samples,
        "seconds": PROBE_SECONDS,
        "short_seconds": SHORT_SPEED_SECONDS,
        "probes": probes,
        "summary": probe_summary(probes),
        "captured": captured_reference(datasets[(src["data"], src["split"])]),
        "expected": _expected(model, probes, samples, datasets, src["data"]),
        "heldout": None,
    }
    if out["expected"] is not None:
        for key in ("speed", "speed_short"):
            out["summary"][f"{key}_follows_captures"] = follows_captures(
                out["summary"][key], out["expected"]["groups"][key], SEPARATION
            )
    return out


def _heldout_report(pairs: list, rows, retrieval, embed, text_cache, warn: list[str]) -> dict:
    """The held-out text cases' part: the (template, held-out) prompt pairs and, with a retrieval model,
    R@k, FID and content accuracy per row."""
    keys = ("r1_template", "r3_template", "r1_heldout", "r3_heldout", "fid", "content_acc")
    out = {
        "cases": len(pairs),
        "pairs": pairs,
        "distinct_template": None,
        "distinct_heldout": None,
        "rows": {row: dict.fromkeys(keys) for row in rows},
        "ranks": None,
    }
    if retrieval is not None:
        texts = ([p["prompt"] for p in pairs], [p["heldout_prompt"] for p in pairs])
        contents = [p["content"] for p in pairs]
        out.update(heldout_retrieval(retrieval, *texts, rows, embed, text_cache, warn, contents))
    return out
