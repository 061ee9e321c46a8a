"""What the captures say the speed probes should do (kinema.evaluate.probe_expectations)."""

from __future__ import annotations

import math

import pytest

from kinema.evaluate.probe_expectations import (
    caption_window_speeds,
    expected_groups,
    follows_captures,
    nearest_captions,
    probe_expectations,
)
from kinema.evaluate.probe_measures import window_speed
from kinema.model.vocabulary import KnownPrompts
from kinema.representation.kimodo_features import features_to_motion
from kinema.text import get_text_encoder

SEP = 2.0


def _probes(*spec):
    return [{"prompt": f"p{i}", "group": g, "caption": c} for i, (g, c) in enumerate(spec)]


def test_expected_groups_pool_each_probe_equally_and_mark_the_steps_the_captures_make():
    speeds = {"slow": {2.0: [0.7, 0.9]}, "walk": {2.0: [1.2] * 50}, "run": {2.0: [2.0, 3.0]}, "dash": {2.0: []}}
    probes = _probes(("1 a", "slow"), ("2 b", "walk"), ("2 b", "run"), ("3 c", "dash"))
    g = expected_groups(probes, speeds, 2.0, samples=3, separation=SEP)
    assert g["1 a"]["mean"] == pytest.approx(0.8) and g["1 a"]["std"] == pytest.approx(0.1)
    # the walk probe's 50 clips count as much as the run probe's 2: mean of the probe means
    assert g["2 b"]["mean"] == pytest.approx((1.2 + 2.5) / 2) and g["2 b"]["clips"] == [50, 2]
    var = ((0.0 + 1.2**2) + (0.25 + 2.5**2)) / 2 - 1.85**2  # the mixture's variance
    assert g["2 b"]["std"] == pytest.approx(math.sqrt(var)) and g["2 b"]["n"] == 6
    se = math.sqrt(0.1**2 / 2 + var / 5)
    assert g["2 b"]["gap"] == pytest.approx(1.05) and 1.05 > SEP * se and g["2 b"]["separated"] is True
    assert g["3 c"]["mean"] is None and "gap" not in g["3 c"]  # no captured clip this long: no step asked


def _model(**means):
    return {g: {"mean": m, "std": 0.1, "n": 6} for g, m in means.items()}


def test_follows_captures_asks_for_exactly_the_steps_the_captures_make():
    expected = {"1": {"mean": 0.8}, "2": {"mean": 1.2, "separated": True}, "3": {"mean": 1.3, "separated": False},
                "4": {"mean": None}}
    assert follows_captures(_model(**{"1": 0.8, "2": 1.3, "3": 1.1, "4": 0.0}), expected, SEP) is True
    assert follows_captures(_model(**{"1": 0.8, "2": 0.85, "3": 3.0, "4": 5.0}), expected, SEP) is False
    assert follows_captures(_model(**{"1": 1.3, "2": 0.8, "3": 3.0, "4": 5.0}), expected, SEP) is False
    none = {"1": {"mean": 0.8}, "2": {"mean": 0.8, "separated": False}, "3": {"mean": None}}
    assert follows_captures(_model(**{"1": 0.8, "2": 0.7, "3": 0.1}), none, SEP) is None


def test_caption_window_speeds_measure_the_clips_that_carry_each_caption(tiny_data):
    from kinema.data.dataset import MotionDataset

    ds = MotionDataset(tiny_data, "all")
    caption = ds.clips[0]["captions"][0]
    carriers = [i for i, r in enumerate(ds.clips) if caption in r["captions"]]
    out = caption_window_speeds(ds, {caption, "no clip says this."}, (1.0, 1e4))
    want = [window_speed(features_to_motion(ds[i]["features"].double(), ds.skeleton, ds.fps), 1.0) for i in carriers]
    assert out[caption][1.0] == pytest.approx([w for w in want if w is not None]) and out[caption][1.0]
    assert out[caption][1e4] == [] and out["no clip says this."] == {1.0: [], 1e4: []}


def test_probe_expectations_name_each_speed_probes_nearest_caption(tiny_data):
    from kinema.data.dataset import MotionDataset

    ds = MotionDataset(tiny_data, "all")
    enc = get_text_encoder("hash-test-32")
    captions = sorted({c for r in ds.clips for c in r["captions"]})
    known = KnownPrompts.build(captions, enc)
    assert nearest_captions([captions[3]], known, enc.encode)[captions[3]][0] == captions[3]
    records = [{"prompt": captions[0], "kind": "speed", "group": "1 x"},
               {"prompt": captions[1], "kind": "speed", "group": "2 y"},
               {"prompt": "A person raises a hand.", "kind": "hand", "group": "left"}]
    exp = probe_expectations(records, known, enc.encode, ds, 3, SEP, {"speed": 1.0, "speed_short": 1e4})
    assert [p["caption"] for p in exp["probes"]] == captions[:2]
    assert all(p["cosine"] == pytest.approx(1.0, abs=1e-3) for p in exp["probes"])
    assert set(exp["groups"]) == {"speed", "speed_short"} and list(exp["groups"]["speed"]) == ["1 x", "2 y"]
    assert all(g["mean"] is None for g in exp["groups"]["speed_short"].values())  # no clip lasts 1e4 s
    assert probe_expectations(records[2:], known, enc.encode, ds, 3, SEP, {"speed": 1.0}) is None


def test_report_shows_what_the_captures_say(tmp_path):
    from kinema.evaluate.phrasings import probe_summary
    from kinema.evaluate.report import format_phrasings_table, plot_phrasings

    recs = [{"prompt": f"p{g}{k}", "kind": "speed", "group": g, "speeds": [v + 0.01 * k, v - 0.01 * k, v],
             "speeds_short": [v, v, v + 0.02]} for g, v in (("1 slow", 0.8), ("2 walk", 1.5), ("3 run", 1.52))
            for k in range(2)]
    speeds = {"slow": {4.0: [0.7, 0.8], 2.0: [0.7]}, "walk": {4.0: [1.2, 1.3], 2.0: [1.2]},
              "run": {4.0: [], 2.0: [1.25]}}
    probes = [{"prompt": r["prompt"], "group": r["group"], "caption": r["group"].split()[1]} for r in recs]
    for p in probes:
        p["window_speed"] = {"speed": None, "speed_short": sum(speeds[p["caption"]][2.0]) / 1}
    groups = {k: expected_groups(probes, speeds, s, 3, SEP) for k, s in (("speed", 4.0), ("speed_short", 2.0))}
    summary = probe_summary(recs)
    summary["speed_follows_captures"] = follows_captures(summary["speed"], groups["speed"], SEP)
    summary["speed_short_follows_captures"] = follows_captures(summary["speed_short"], groups["speed_short"], SEP)
    assert summary["speed_follows_captures"] is True  # the only step the 4-s captures make: slow -> walk
    ph = {"samples": 3, "seconds": 4.0, "short_seconds": 2.0, "probes": recs, "summary": summary,
          "captured": {"speed": {}, "window_speed": {}, "hand": {}}, "expected": {"probes": probes, "groups": groups},
          "heldout": None}
    table = format_phrasings_table({"phrasings": ph, "meta": {"split": ["test"]}})
    assert "| 2 walk | 2 | 6 |" in table and "1.25 ± 0.05, step |" in table and "no captured clip this long |" in table
    assert "the model makes every step the captures make: yes." in table
    assert plot_phrasings({"phrasings": ph}, tmp_path / "p.png") and (tmp_path / "p.png").stat().st_size > 1000
