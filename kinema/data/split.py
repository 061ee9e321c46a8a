"""Deterministic train/val/test split of Bandai Namco clips, by take and never by frame.

Splitting by frame (or by window) would put neighbouring frames of one performance on both
sides and make validation numbers meaningless, so the unit is the clip (one take). The split
must not change between machines, Python versions or runs, so it is derived from a SHA-256 of
the clip id instead of Python's salted `hash()` or a random generator.

Mirrored copies: augmentation makes a left/right mirrored copy of every clip. The copy has no
clip id of its own here: callers always pass the *original* clip id (the one parsed from the
file name), so a clip and its mirror land in the same split by construction.
"""

from __future__ import annotations

import hashlib
import re
from collections import defaultdict
from pathlib import PurePath

from kinema.errors import DataError

SPLITS = ("train", "val", "test")

_LABEL = r"[a-z0-9]+(?:-[a-z0-9]+)*"
_CLIP_NAME = re.compile(
    rf"^(?P<dataset>dataset-\d+)_(?P<content>{_LABEL})_(?P<style>{_LABEL})_(?P<take>\d+)"
    r"(?:\.bvh\.gz|\.bvh|\.json)?$"
)


def parse_clip_name(filename: str) -> dict:
    """Fields of a clip file name such as `dataset-2_wave-left-hand_normal_012.bvh.gz`.

    Returns {"dataset": "dataset-2", "content": "wave-left-hand", "style": "normal",
    "take": 12, "clip_id": "dataset-2_wave-left-hand_normal_012"}. Leading folders are ignored
    and the suffix may be `.bvh.gz`, `.bvh`, `.json` or absent (a bare clip id). Labels contain
    hyphens but never underscores, which is what makes the name unambiguous. Raises `DataError`
    for names that do not fit.
    """
    name = PurePath(str(filename)).name
    m = _CLIP_NAME.match(name)
    if m is None:
        raise DataError(f"{name!r} is not a clip name of the form dataset-N_<content>_<style>_<take>[.bvh.gz]")
    take_text = m.group("take")
    return {
        "dataset": m.group("dataset"),
        "content": m.group("content"),
        "style": m.group("style"),
        "take": int(take_text),
        "clip_id": f"{m.group('dataset')}_{m.group('content')}_{m.group('style')}_{take_text}",
    }


def group_of(clip_id: str) -> str:
    """The stratification group of a clip: `<dataset>_<content>`, e.g. `dataset-2_walk`."""
    fields = parse_clip_name(clip_id)
    return f"{fields['dataset']}_{fields['content']}"


def _check_fractions(fractions: tuple[float, float, float]) -> tuple[float, float, float]:
    """Validate (train, val, test) fractions: three non-negative numbers summing to 1."""
    if len(fractions) != 3 or any(f < 0 for f in fractions) or abs(sum(fractions) - 1.0) > 1e-6:
        raise ValueError(f"fractions must be three non-negative numbers summing to 1, got {fractions!r}")
    train, val, test = (float(f) for f in fractions)
    return train, val, test


def _unit(clip_id: str, group: str) -> float:
    """A number in [0, 1) fixed by (group, clip id): the first 8 bytes of a SHA-256."""
    digest = hashlib.sha256(f"{group}/{clip_id}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2.0**64


def split_for(clip_id: str, group: str, fractions=(0.8, 0.1, 0.1)) -> str:
    """Split of one clip from its hash alone: "train", "val" or "test".

    The clip's number u in [0, 1) (SHA-256 of "group/clip_id") is compared with the cumulative
    fractions: u < train -> "train", u < train + val -> "val", else "test". This needs no other
    clip, but small groups may end up with no test clip; `assign_splits` ranks the same numbers
    inside each group to guarantee coverage and agrees with this rule for almost every clip.
    Pass the original clip id for mirrored copies.
    """
    train, val, _ = _check_fractions(fractions)
    u = _unit(clip_id, group)
    if u < train:
        return "train"
    if u < train + val:
        return "val"
    return "test"


def _counts(n: int, fractions: tuple[float, float, float]) -> tuple[int, int, int]:
    """How many of a group's n clips go to (train, val, test); see `assign_splits`."""
    _, val, test = fractions
    if n < 3:
        return n, 0, 0
    n_test = max(1, round(n * test)) if test > 0 else 0
    n_val = max(1, round(n * val)) if val > 0 else 0
    while n - n_test - n_val < 1:  # keep at least one training clip
        if n_val > 0:
            n_val -= 1
        else:
            n_test -= 1
    return n - n_val - n_test, n_val, n_test


def assign_splits(clips: list[tuple[str, str]], fractions=(0.8, 0.1, 0.1)) -> dict[str, str]:
    """Stratified split of (clip_id, group) pairs: {clip_id: "train" | "val" | "test"}.

    Rule, applied to each group on its own (a group is normally `group_of(clip_id)`, i.e. the
    dataset and content, so every motion type is represented in every split):

    1. sort the group's clips by the hash number u used by `split_for` (ties by clip id);
    2. with n clips: n < 3 -> all "train"; otherwise n_test = max(1, round(n * test)) and
       n_val = max(1, round(n * val)) (0 when that fraction is 0), shrunk if needed so that
       at least one clip stays in "train";
    3. the n_test clips with the largest u go to "test", the next n_val to "val", the rest to
       "train" - the same ordering as `split_for`, so both rules mostly agree.

    The result depends only on the set of pairs (not their order, machine or Python version).
    Adding takes to a group can move clips that sit at a boundary. Mirrored copies must not be
    listed: they take the split of their original clip id. Raises `DataError` if one clip id is
    given with two different groups.
    """
    fr = _check_fractions(fractions)
    groups: dict[str, set[str]] = defaultdict(set)
    seen: dict[str, str] = {}
    for clip_id, group in clips:
        if seen.setdefault(clip_id, group) != group:
            raise DataError(f"clip {clip_id!r} is listed in two groups: {seen[clip_id]!r} and {group!r}")
        groups[group].add(clip_id)
    result: dict[str, str] = {}
    for group, members in groups.items():
        ranked = sorted(members, key=lambda c, g=group: (_unit(c, g), c))
        n_train, n_val, _ = _counts(len(ranked), fr)
        for rank, clip_id in enumerate(ranked):
            if rank < n_train:
                result[clip_id] = "train"
            elif rank < n_train + n_val:
                result[clip_id] = "val"
            else:
                result[clip_id] = "test"
    return result


def assign_rig_splits(
    rig_clips: dict[str, int], fractions=(0.8, 0.1, 0.1), *, train: frozenset[str] = frozenset()
) -> dict[str, str]:
    """Split whole rigs (skeletons) of a multi-rig dataset: {rig_id: "train" | "val" | "test"}.

    Every clip of a rig lands in its rig's split, so val and test measure how a model does on
    skeletons it never saw. ``rig_clips`` maps each rig id to its clip count. Rule: rigs are ranked
    by a SHA-256 of their id (as in `assign_splits`; ties by id); walking that order, a rig goes to
    "test" while test holds fewer than ``test`` of all clips and the rig would not take test past
    twice that share, then likewise to "val"; every other rig is "train". With three or more rigs,
    val and test get at least one rig each (the first in hash order that fits, else the smallest)
    and at least one rig stays in train. Fewer than three rigs are all train. Deterministic.
    Rigs named in ``train`` are then moved to train (the others keep their split, so held-out shares
    shrink rather than other rigs moving): a kind of skeleton the model must know (a biped dinosaur)
    is not held out by chance.
    """
    _, f_val, f_test = _check_fractions(fractions)
    unknown = sorted(set(train) - set(rig_clips))
    if unknown:
        raise DataError(f"train rigs {unknown} are not rigs of this build (rigs: {', '.join(sorted(rig_clips))})")
    ranked = sorted(rig_clips, key=lambda r: (_unit(r, "rig"), r))
    result = dict.fromkeys(ranked, "train")
    if len(ranked) < 3:
        return result
    total = max(1, sum(rig_clips.values()))
    held = [(split, frac) for split, frac in (("test", f_test), ("val", f_val)) if frac > 0]
    for k, (split, frac) in enumerate(held):
        reserve = len(held) - k  # rigs still needed: one per later held-out split, one for train
        taken = 0
        for r in [r for r in ranked if result[r] == "train"]:
            if taken / total >= frac or sum(v == "train" for v in result.values()) <= reserve:
                break
            if (taken + rig_clips[r]) / total <= 2 * frac:
                result[r] = split
                taken += rig_clips[r]
        free = [r for r in ranked if result[r] == "train"]
        if taken == 0 and len(free) > reserve:
            result[min(free, key=lambda r: (rig_clips[r], _unit(r, "rig"), r))] = split
    return result | dict.fromkeys(train, "train")
