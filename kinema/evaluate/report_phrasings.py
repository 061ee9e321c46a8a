"""The "Prompts in other words" part of an evaluation report (kinema.evaluate.phrasings; markdown).

Speeds in m/s, heights in metres; the keys read are those docs/evaluation.md lists for ``phrasings``.
"""

from __future__ import annotations

from kinema.evaluate.probe_measures import SIDE_MARGIN

__all__ = ["fmt", "format_phrasings_table"]


def fmt(value, scale: float = 1.0, decimals: int = 2) -> str:
    return "-" if value is None else f"{value * scale:.{decimals}f}"


def _pm(stats: dict | None) -> str:
    return "-" if not stats else f"{stats['mean']:.2f} ± {stats['std']:.2f} ({stats['min']:.2f}-{stats['max']:.2f})"


def _clip_speeds(by_content: dict) -> str:
    """'walk 1.20 ± ... over n clips; run ...' for captured speed stats by content ('' when none)."""
    return "; ".join(f"{c} {_pm(v)} over {v['n']} clips" for c, v in by_content.items())


def _of(fraction: float | None, n: int) -> str:
    """``k/n`` for a fraction of n samples ('-' when absent: a report written before the measure)."""
    return "-" if fraction is None else f"{round(fraction * n)}/{n}"


def _speed_table(groups: dict, ordered, samples: int, seconds: float, captured: str,
                 expected: dict | None = None, follows=None) -> list[str]:
    """Markdown lines of one speed-probe table (groups of kinema.evaluate.phrasings.speed_groups; with
    ``expected``, kinema.evaluate.probe_expectations groups, a column of what the captures say)."""
    order, follow = ({True: "yes", False: "**no**", None: "-"}[v] for v in (ordered, follows))
    exp = expected or {}
    lines = [f"Speed probes ({samples} samples of {seconds:g} s each, raw; pelvis ground speed, m/s, "
             "mean ± sd (min-max)):", "",
             "| Group | Probes | Samples | Speed (m/s) | Faster than the one above (m/s) | "
             "Captures of the nearest captions (m/s) |", "|---|---:|---:|---|---|---|"]
    for g, v in groups.items():
        gap = "-" if "gap" not in v else f"{v['gap']:+.2f} ± {v['gap_se']:.2f}" + ("" if v["separated"] else " (no)")
        lines.append(f"| {g} | {v['probes']} | {v['n']} | {_pm(v)} | {gap} | {_expected_cell(exp.get(g))} |")
    lines += ["", f"Groups in order (slow walk < walk < jog < sprint, each mean over 2 standard errors above "
              f"the one before): {order}. {captured}", ""]
    if expected:
        lines += [f"The captures of each probe's nearest training caption, {seconds:g}-s windows, make the steps "
                  "marked 'step' (same rule, same sample counts); the model makes every step the captures "
                  f"make: {follow}.", ""]
    return lines


def _expected_cell(v: dict | None) -> str:
    """'2.67 ± 0.55, step' for an expected group (kinema.evaluate.probe_expectations)."""
    if not v or v["mean"] is None:
        return "no captured clip this long"
    step = "" if "separated" not in v else (", step" if v["separated"] else ", no step")
    return f"{v['mean']:.2f} ± {v['std']:.2f}{step}"


def format_phrasings_table(data: dict) -> str:
    """The "Prompts in other words" tables (markdown; kinema.evaluate.phrasings), or "" when not run."""
    ph = data.get("phrasings")
    if not ph:
        return ""
    summ, cap = ph["summary"], ph["captured"]
    lines = ["Probes and held-out captions use verb phrases that no training caption contains "
             "(kinema.data.phrasings; docs/evaluation.md).", ""]
    exp = (ph.get("expected") or {}).get("groups", {})
    lines += _speed_table(summ["speed"], summ["speed_ordered"], ph["samples"], ph["seconds"],
                          f"Captured ({', '.join(data['meta']['split'])} split, same measure): "
                          f"{_clip_speeds(cap['speed']) or 'no walk/run/dash clips'}.",
                          exp.get("speed"), summ.get("speed_follows_captures"))
    if summ.get("speed_short"):
        lines += _speed_table(summ["speed_short"], summ["speed_short_ordered"], ph["samples"], ph["short_seconds"],
                              f"Captured {ph['short_seconds']:g}-s windows (every 0.5 s, mean per clip): "
                              f"{_clip_speeds(cap.get('window_speed', {})) or 'none'}. Every captured run covers "
                              "the ~8 m capture room, so the "
                              f"captured runs that last {ph['seconds']:g} s are mostly the slow ones; at "
                              f"{ph['short_seconds']:g} s they hold slow, medium and fast runs.",
                              exp.get("speed_short"), summ.get("speed_short_follows_captures"))
    lines += ["| Hand probe | Hand | Side followed | Raised | Hand over head (m) | Other hand over head (m) |",
              "|---|---|---:|---:|---:|---:|"]
    lines += [f"| {h['prompt']} | {h['hand']} | {_of(h.get('side_fraction'), h['samples'])} | "
              f"{_of(h['raised_fraction'], h['samples'])} | {h['hand_over_head_m']:.2f} | "
              f"{h['other_over_head_m']:.2f} |" for h in summ["hand"]]
    flagged = [f'"{r["prompt"]}"' for r in ph["probes"] if r.get("unknown_warning")]
    hands = "; ".join(f"{s} {v['raised_fraction'] * 100:.0f} % raised, "
                      + ("" if "side_fraction" not in v else f"{v['side_fraction'] * 100:.0f} % side followed, ")
                      + f"of {v['clips']} clips" for s, v in cap["hand"].items())
    lines += ["", f"Side followed = the named hand gets {SIDE_MARGIN:g} m higher than the other hand; raised = it gets "
              f"above the head and higher than the other hand. Captured raise-up-*-hand clips by these measures: "
              f"{hands or 'none in the split'} (the feminine style's captures raise the hand to 0.14 m below the "
              f"head: docs/evaluation.md). Probes the model "
              f"warned are far from its training captions: {', '.join(flagged) or 'none'}."]
    ho = ph.get("heldout")
    if ho:
        lines += ["", f"Text cases again from held-out captions ({ho['cases']} cases, same seeds; "
                  f"{ho['distinct_template']} distinct template / {ho['distinct_heldout']} distinct held-out "
                  "captions):",
                  "", "| Motions | R@1 / R@3 template captions (%) | R@1 / R@3 held-out captions (%) | FID | "
                  "Content acc. (%) |", "|---|---:|---:|---:|---:|"]
        names = {"ground_truth": "Ground truth", "template": "Model (raw), template prompt",
                 "heldout": "Model (raw), held-out prompt"}
        for row, v in ho["rows"].items():
            r_t = f"{fmt(v['r1_template'], 100, 1)} / {fmt(v['r3_template'], 100, 1)}"
            r_h = f"{fmt(v['r1_heldout'], 100, 1)} / {fmt(v['r3_heldout'], 100, 1)}"
            lines.append(f"| {names.get(row, row)} | {r_t} | {r_h} | {fmt(v['fid'], 1, 3)} | "
                         f"{fmt(v.get('content_acc'), 100, 1)} |")
        lines += ["", "Content acc. = the nearest ground-truth clip of the text cases (retrieval motion embedding) "
                  "has the case's content label (the ground truth: its nearest other clip); no captions involved, "
                  "so style words and the retrieval model's reading of paraphrases do not count."]
    return "\n".join(lines)
