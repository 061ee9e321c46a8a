"""What the captures say a speed probe should do: the training clips behind its nearest training caption.

Why: a held-out prompt can only be followed as far as the data hold its words. Each speed probe
(kinema.data.phrasings.PROBES) has a nearest training caption (cosine of the MiniLM embeddings, as the
unknown-prompt warning and prompt grounding find it: "Somebody jogs ahead." -> "A person runs ahead.",
"A man jogs quickly forward." -> "A man sprints forward."). The training clips that carry that caption
are what the model learned those words from; their speed over windows of the probe's length (every
0.5 s, kinema.evaluate.probe_measures.window_speed) is what a model that reproduces its data would
give. Pooled per speed group, with the probes' own sample count, they say which steps of the order
slow walk < walk < jog < sprint the captures themselves make (same rule as the model's groups:
:data:`kinema.evaluate.phrasings.SEPARATION` standard errors), and :func:`follows_captures` asks the
model for exactly those. Where the captures hold no clip of the length (every captured dash is shorter
than 4 s), the group has no expectation and its step is not asked for.

Speeds in m/s (pelvis, horizontal); lengths in seconds.
"""

from __future__ import annotations

import math

from kinema.evaluate.probe_measures import group_step, window_speed
from kinema.representation.kimodo_features import features_to_motion


def nearest_captions(prompts: list[str], known, encode) -> dict[str, tuple[str, float]]:
    """Prompt -> (nearest training caption, cosine); ``known``: kinema.model.vocabulary.KnownPrompts,
    ``encode(list[str]) -> (N, E)`` the model's text encoder."""
    emb = encode(prompts)
    return {p: known.match(p, emb[i]).nearest[0] for i, p in enumerate(prompts)}


def caption_window_speeds(dataset, captions: set[str], seconds: tuple[float, ...]) -> dict[str, dict[float, list]]:
    """Caption -> length -> window speeds (one per clip long enough) of the dataset's clips carrying it."""
    out: dict[str, dict[float, list]] = {c: {s: [] for s in seconds} for c in captions}
    for i, rec in enumerate(dataset.clips):
        hits = captions.intersection(rec["captions"])
        if not hits:
            continue
        m = features_to_motion(dataset[i]["features"].double(), dataset.skeleton, dataset.fps)
        for s in seconds:
            w = window_speed(m, s)
            if w is not None:
                for c in hits:
                    out[c][s].append(w)
    return out


def _moments(values: list[float]) -> tuple[float, float]:
    mean = sum(values) / len(values)
    return mean, sum((v - mean) ** 2 for v in values) / len(values)


def expected_groups(probes: list[dict], speeds: dict, seconds: float, samples: int, separation: float) -> dict:
    """Per speed group: the mixture of its probes' captured window speeds at ``seconds`` (each probe
    weighted equally, as each gets ``samples`` samples): ``mean``, ``std``, ``clips`` per probe; from the
    second group with data on, ``gap`` and ``separated`` (gap > ``separation`` standard errors at the
    groups' sample counts). A group none of whose probes has clips that long has ``mean`` None."""
    groups: dict[str, dict] = {}
    for g in sorted({p["group"] for p in probes}):
        mine = [p for p in probes if p["group"] == g]
        per = [speeds[p["caption"]][seconds] for p in mine]
        with_data = [_moments(v) for v in per if v]
        entry = {"probes": len(mine), "clips": [len(v) for v in per], "n": samples * len(mine), "mean": None}
        if with_data:
            mean = sum(m for m, _ in with_data) / len(with_data)
            var = sum(v + m * m for m, v in with_data) / len(with_data) - mean * mean
            entry.update(mean=mean, std=math.sqrt(max(var, 0.0)))
        groups[g] = entry
    names = [g for g in groups if groups[g]["mean"] is not None]
    for prev, g in zip(names, names[1:], strict=False):
        gap, _, separated = group_step(groups[prev], groups[g], separation)
        groups[g].update(gap=gap, separated=separated)
    return groups


def follows_captures(model_groups: dict, expected: dict, separation: float) -> bool | None:
    """Whether the model's speed groups (kinema.evaluate.phrasings.speed_groups) make every step the
    captures make (:func:`expected_groups`: consecutive groups with captured data, the second faster by
    over ``separation`` standard errors), by the same rule; None when the captures make no step."""
    names = [g for g in expected if expected[g]["mean"] is not None and g in model_groups]
    asked = [(a, b) for a, b in zip(names, names[1:], strict=False) if expected[b].get("separated")]
    if not asked:
        return None
    return all(group_step(model_groups[a], model_groups[b], separation)[2] for a, b in asked)


def probe_expectations(records: list[dict], known, encode, dataset, samples: int, separation: float,
                       lengths: dict[str, float]) -> dict | None:
    """The phrasings part's ``expected``: per speed probe its nearest training caption and captured window
    speeds, per length key (``speed`` / ``speed_short`` -> seconds) the expected groups; None without
    speed probes."""
    speed = [r for r in records if r["kind"] == "speed"]
    if not speed:
        return None
    nearest = nearest_captions([r["prompt"] for r in speed], known, encode)
    speeds = caption_window_speeds(dataset, {c for c, _ in nearest.values()}, tuple(lengths.values()))
    probes = [{"prompt": r["prompt"], "group": r["group"], "caption": nearest[r["prompt"]][0],
               "cosine": nearest[r["prompt"]][1]} for r in speed]
    for p in probes:
        p["window_speed"] = {key: _mean_or_none(speeds[p["caption"]][s]) for key, s in lengths.items()}
    return {
        "probes": probes,
        "groups": {key: expected_groups(probes, speeds, s, samples, separation) for key, s in lengths.items()},
    }


def _mean_or_none(values: list[float]) -> float | None:
    return sum(values) / len(values) if values else None
