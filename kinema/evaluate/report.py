"""Write evaluation results: ``report.md`` (Kimodo Table 1 layout), ``report.json`` and plots.

``write_report(results, out_dir)`` takes the :class:`kinema.evaluate.runner.EvalResults` of
``run_suite`` and writes, each file atomically (temp file + rename):

- ``report.json``: ``results.data`` plus ``"plots"`` (the keys are documented in docs/evaluation.md);
- ``report.md``: the summary table (rows ground truth / raw / post-processed), distribution metrics,
  per-kind errors, timing and warnings;
- ``plots/keyframes.png`` (constraint error vs number of keyframes), ``plots/foot_skate.png``
  (per-case foot skate, GT vs raw vs post) and ``plots/filmstrip_<case>.png`` for a few generated cases.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from kinema.atomic_files import atomic_write_bytes
from kinema.evaluate.report_phrasings import fmt as _fmt
from kinema.evaluate.report_phrasings import format_phrasings_table

ROW_LABELS = {"ground_truth": "Ground truth", "raw": "Model (raw)", "post": "Model (post-processed)"}
#: (column key, header, scale, decimals) of the main table, in Kimodo Table 1 order
TABLE = (
    ("r1_whole", "R@1 (%)", 100.0, 1),
    ("r3_whole", "R@3 (%)", 100.0, 1),
    ("r3_batch32", "R@3 b32 (%)", 100.0, 1),
    ("fid", "FID", 1.0, 3),
    ("foot_skate_cm_s", "Skate (cm/s)", 1.0, 2),
    ("contact_acc", "Contact", 1.0, 3),
    ("fullbody_pos_cm", "Full-body pos (cm)", 1.0, 2),
    ("ee_pos_cm", "EE pos (cm)", 1.0, 2),
    ("ee_rot_deg", "EE rot (deg)", 1.0, 2),
    ("root2d_pos_cm", "2D root pos (cm)", 1.0, 2),
    ("pelvis_p95_cm", "2D pelvis p95 (cm)", 1.0, 2),
    ("jerk", "Jerk (m/s^3)", 1.0, 1),
)
COLOURS = {"ground_truth": "#555555", "raw": "#e0452b", "post": "#1f6fd1"}


def format_table(data: dict) -> str:
    """The main table (markdown) of a report.json dict."""
    head = "| Method | " + " | ".join(h for _, h, _, _ in TABLE) + " |"
    sep = "|---|" + "|".join("---:" for _ in TABLE) + "|"
    lines = [head, sep]
    for row, vals in data["table"].items():
        cells = [_fmt(vals.get(k), s, d) for k, _, s, d in TABLE]
        lines.append(f"| {ROW_LABELS.get(row, row)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_timeline_table(data: dict) -> str:
    """The timeline table (markdown; kinema.evaluate.timeline), or "" when the suite has no timeline case."""
    tl = data.get("timeline")
    if not tl:
        return ""
    lines = ["| Method | Cases | Segments | R@1 (%) | R@3 (%) | Skate (cm/s) | Speed join / inside (m/s) | "
             "Acc join / inside (m/s^2) | Acc peak join / inside p99 (m/s^2) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row, v in tl.items():
        lines.append(
            f"| {ROW_LABELS.get(row, row)} | {v['cases']} | {v['segments']} | {_fmt(v['r1'], 100, 1)} | "
            f"{_fmt(v['r3'], 100, 1)} | {_fmt(v['foot_skate_cm_s'])} | {_fmt(v['join_speed'])} / "
            f"{_fmt(v['inside_speed'])} | {_fmt(v['join_acc'], 1, 1)} / {_fmt(v['inside_acc'], 1, 1)} | "
            f"{_fmt(v['join_acc_peak'], 1, 0)} / {_fmt(v['inside_acc_p99'], 1, 0)} |")
    return "\n".join(lines)


def _markdown(data: dict) -> str:
    meta, timing, text = data["meta"], data["timing"], data["text"]
    rows = list(data["table"])
    out = [
        "# kinema evaluation report", "",
        f"Model `{meta['model']}` at {meta['fps']:g} fps; {meta['num_cases']} cases from "
        f"{', '.join(meta['data'])} ({', '.join(meta['split'])}); seed {meta['seed']}, "
        f"DDIM steps {meta['steps'] if meta['steps'] is not None else 'model default'}; guidance "
        f"{meta.get('guidance', 'model default')}; "
        f"root displacement {'on' if meta.get('root_displacement') else 'off'}, "
        f"root smoothing {meta.get('root_smoothing', 0.0):g} s, "
        f"joint displacement {meta.get('joint_sigma', 0.0):g} s. "
        "Protocol and metric definitions: docs/evaluation.md.", "",
        "## Summary (layout of Kimodo Table 1)", "",
        format_table(data), "",
        f"R@k and FID use the retrieval model over the {text['cases']} text cases (R@k 'whole' ranks among all of "
        f"them, 'b32' in random batches of {text['r_batch_size']}); skate, contact and jerk are over text cases; "
        "constraint errors average over the cases with that constraint type; pelvis p95 pools every root-2D "
        "keyframe. FID is not scaled (Kimodo prints FID x 100).", "",
        "## Distribution", "",
        "| Method | Diversity | Multimodality | Coverage AUC | Novelty AUC |", "|---|---:|---:|---:|---:|",
    ]
    out += _distribution_rows(data, rows) + _by_kind_section(data, rows)
    if data.get("timeline"):
        n = next(iter(data["timeline"].values()))["segments"]
        out += ["", "## Timelines", "", format_timeline_table(data), "",
                "Each timeline case chains 2-4 test captions; R@k ranks each segment's frames against the captions "
                f"of all {n} timeline segments (chance R@3 {300 / max(n, 1):.1f} %); joins are the frames from "
                "0.5 s before to 0.25 s after each segment boundary (docs/evaluation.md)."]
    out += ["", "## Prompts in other words", "", format_phrasings_table(data)] if data.get("phrasings") else []
    out += ["", "## Timing", "",
            f"Wall time {timing['wall_seconds']:.1f} s, of which generation {timing['generate_seconds']:.1f} s "
            f"({timing['seconds_per_case']:.2f} s per generated motion, {meta['torch_threads']} torch threads, "
            f"{meta['machine']}).", ""]
    plots = data.get("plots", {})
    if plots:
        out += ["## Plots", ""]
        for name in ("keyframes", "foot_skate", "phrasings"):
            if plots.get(name):
                out.append(f"![{name}]({plots[name]})")
        out += [f"![{Path(p).stem}]({p})" for p in plots.get("filmstrips", [])]
        out.append("")
    if data["warnings"]:
        out += ["## Warnings", ""] + [f"- {w}" for w in data["warnings"]] + [""]
    return "\n".join(out)


def _distribution_rows(data: dict, rows: list[str]) -> list[str]:
    """One line per method of the distribution table (diversity, multimodality, coverage, novelty)."""
    out = []
    for row in rows:
        v = data["table"][row]
        out.append(f"| {ROW_LABELS.get(row, row)} | {_fmt(v.get('diversity'), 1, 3)} | "
                   f"{_fmt(v.get('multimodality'), 1, 3)} | {_fmt(v.get('coverage_auc'), 1, 3)} | "
                   f"{_fmt(v.get('novelty_auc'), 1, 3)} |")
    return out


def _by_kind_section(data: dict, rows: list[str]) -> list[str]:
    """The "By case kind" section: skate, contact and constraint errors per case kind and method."""
    out = ["", "## By case kind", "",
           "| Kind | Method | Cases | Skate (cm/s) | Contact | Full-body (cm) | EE pos (cm) | EE rot (deg) | "
           "Root 2D (cm) | Pelvis p95 (cm) |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    kinds = list(dict.fromkeys(k for row in rows for k in data["by_kind"].get(row, {})))
    for kind in kinds:
        for row in rows:
            v = data["by_kind"][row].get(kind)
            if v:
                cells = [_fmt(v[k]) if k != "contact_acc" else _fmt(v[k], 1, 3)
                         for k in ("foot_skate_cm_s", "contact_acc", "fullbody_pos_cm", "ee_pos_cm", "ee_rot_deg",
                                   "root2d_pos_cm", "pelvis_p95_cm")]
                out.append(f"| {kind} | {ROW_LABELS.get(row, row)} | {v['cases']} | " + " | ".join(cells) + " |")
    return out


# ----------------------------------------------------------------------------- plots
def _save_fig(fig, path: Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", facecolor="white")
    atomic_write_bytes(path, buf.getvalue())


def plot_keyframes(data: dict, path: Path) -> bool:
    """Error vs number of keyframes per sparse kind (case values as dots, mean per K as lines)."""
    from matplotlib.figure import Figure

    kinds = list(data["by_keyframes"])
    if not kinds:
        return False
    fig = Figure(figsize=(4.2 * len(kinds), 3.4), dpi=100, layout="constrained")
    for n, kind in enumerate(kinds):
        info = data["by_keyframes"][kind]
        ax = fig.add_subplot(1, len(kinds), n + 1)
        for row in data["table"]:
            pts = [(c["num_keyframes"], c["metrics"][row][info["metric"]]) for c in data["cases"]
                   if c["kind"] == kind and c["num_keyframes"] and c["metrics"][row][info["metric"]] is not None]
            if pts:
                ax.scatter(*zip(*pts, strict=True), s=12, alpha=0.4, color=COLOURS.get(row))
            line = [(p["num_keyframes"], p["error"]) for p in info[row] if p["error"] is not None]
            if line:
                ax.plot(*zip(*line, strict=True), "-o", ms=3, color=COLOURS.get(row), label=ROW_LABELS.get(row, row))
        ax.set_title(kind)
        ax.set_xlabel("keyframes")
        ax.set_ylabel(info["metric"].replace("_", " "))
        ax.grid(alpha=0.3)
        if n == 0:
            ax.legend(fontsize=8)
    _save_fig(fig, path)
    return True


def plot_foot_skate(data: dict, path: Path) -> bool:
    """Per-case foot skate (cm/s) of every row: box plots with the cases as dots."""
    from matplotlib.figure import Figure

    rows = list(data["table"])
    values = [[c["metrics"][r]["foot_skate_cm_s"] for c in data["cases"] if c["metrics"][r]["foot_skate_samples"]]
              for r in rows]
    if not any(values):
        return False
    fig = Figure(figsize=(5.5, 3.6), dpi=100, layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    rng = np.random.default_rng(0)
    for n, (row, vals) in enumerate(zip(rows, values, strict=True)):
        if vals:
            ax.boxplot([vals], positions=[n], widths=0.5, showfliers=False)
            ax.scatter(n + rng.uniform(-0.15, 0.15, len(vals)), vals, s=10, alpha=0.5, color=COLOURS.get(row))
    ax.set_xticks(range(len(rows)), [ROW_LABELS.get(r, r) for r in rows])
    ax.set_ylabel("foot skate (cm/s)")
    ax.set_title("Foot skate per case (contact frames)")
    ax.grid(alpha=0.3, axis="y")
    _save_fig(fig, path)
    return True


def _plot_speed_probes(ax, ph: dict, speed: list[dict]) -> None:
    """Every speed-probe sample at both lengths against the captured walk/run/dash speeds, and a bar at
    what the captures of each probe's nearest training caption do (kinema.evaluate.probe_expectations)."""
    for content, colour in (("walk", "#2a9d4b"), ("run", "#e0452b"), ("dash", "#7b3fbf")):
        v = ph["captured"]["speed"].get(content)
        if v:
            ax.axhspan(v["mean"] - v["std"], v["mean"] + v["std"], color=colour, alpha=0.12)
            ax.axhline(v["mean"], color=colour, ls="--", lw=1, label=f"captured {content}: mean ± sd, {v['n']} clips")
    expected = {p["prompt"]: p["window_speed"] for p in (ph.get("expected") or {}).get("probes", [])}
    labelled = False
    for n, r in enumerate(speed):
        ax.scatter([n - 0.12] * len(r["speeds"]), r["speeds"], s=18, color="#1f6fd1",
                   label=f"{ph['seconds']:g}-s samples" if n == 0 else None)
        if "speeds_short" in r:
            ax.scatter([n + 0.12] * len(r["speeds_short"]), r["speeds_short"], s=18, color="#f08c00",
                       label=f"{ph['short_seconds']:g}-s samples" if n == 0 else None)
        for dx, key in ((-0.12, "speed"), (0.12, "speed_short")):
            v = expected.get(r["prompt"], {}).get(key)
            if v is not None:
                ax.scatter([n + dx], [v], marker="_", s=220, color="black", linewidths=2,
                           label=None if labelled else "captures of its nearest caption, same length")
                labelled = True
    ax.set_xticks(range(len(speed)), [f"{r['group']}: {r['prompt']}" for r in speed], rotation=35, ha="right",
                  fontsize=7)
    ax.set_ylabel("pelvis ground speed (m/s)")
    ax.set_title("Speed probes (raw, every sample)")
    ax.grid(alpha=0.3, axis="y")
    ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]), top=ax.get_ylim()[1] * 1.45)  # headroom for the legend
    ax.legend(fontsize=6, loc="upper left", ncol=2)


def plot_phrasings(data: dict, path: Path) -> bool:
    """Probes: speed of every sample per speed probe against the captured walk/run speeds (left), and
    the named vs other hand's height over the head per hand probe sample (right)."""
    from matplotlib.figure import Figure

    ph = data.get("phrasings")
    if not ph:
        return False
    speed = [r for r in ph["probes"] if r["kind"] == "speed"]
    hand = [r for r in ph["probes"] if r["kind"] == "hand"]
    fig = Figure(figsize=(12.5, 4.6), dpi=100, layout="constrained")
    _plot_speed_probes(fig.add_subplot(1, 2, 1), ph, speed)
    ax = fig.add_subplot(1, 2, 2)
    for n, r in enumerate(hand):
        ax.scatter([n - 0.1] * len(r["hand_over_head"]), r["hand_over_head"], s=18, color="#1f6fd1",
                   label="named hand" if n == 0 else None)
        ax.scatter([n + 0.1] * len(r["other_over_head"]), r["other_over_head"], s=18, color="#999999",
                   label="other hand" if n == 0 else None)
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xticks(range(len(hand)), [f"{r['group']}: {r['prompt']}" for r in hand], rotation=35, ha="right",
                  fontsize=7)
    ax.set_ylabel("highest over the head (m)")
    ax.set_title("Hand probes (raw; > 0 = above the head)")
    ax.grid(alpha=0.3, axis="y")
    if hand:
        ax.legend(fontsize=7)
    _save_fig(fig, path)
    return True


def _render_targets(case: dict) -> list:
    """Filmstrip targets of a case: end-effector positions and root waypoints (paths thinned)."""
    out = []
    for c in case.get("constraints", []):
        frames = c["frame_indices"]
        if "positions" in c:
            out += [(f, p, c["type"]) for f, p in zip(frames, c["positions"], strict=True)]
        elif c["type"] == "root2d":
            step = max(1, len(frames) // 12) if c.get("dense") else 1
            out += [(f, p) for f, p in list(zip(frames, c["smooth_root_2d"], strict=True))[::step]]
        elif c["type"] == "fullbody":
            out += [(f, p, "pelvis") for f, p in zip(frames, c["root_positions"], strict=True)]
    return out


def pick_filmstrip_cases(cases: list[dict], n: int) -> list[dict]:
    """Up to ``n`` cases, one per kind first (constrained kinds before text)."""
    picked, seen = [], set()
    for c in sorted(cases, key=lambda c: c["kind"] == "text"):
        if c["kind"] not in seen and len(picked) < n:
            picked.append(c)
            seen.add(c["kind"])
    for c in cases:
        if len(picked) >= n:
            break
        if c not in picked:
            picked.append(c)
    return picked


def write_report(results, out_dir, filmstrips: int = 4) -> dict:
    """Write report.json, report.md and plots into ``out_dir``; returns the report.json dict."""
    from kinema.render import render_filmstrip

    out = Path(out_dir)
    (out / "plots").mkdir(parents=True, exist_ok=True)
    data = dict(results.data)
    plots: dict = {"keyframes": None, "foot_skate": None, "phrasings": None, "filmstrips": []}
    if plot_keyframes(data, out / "plots" / "keyframes.png"):
        plots["keyframes"] = "plots/keyframes.png"
    if plot_foot_skate(data, out / "plots" / "foot_skate.png"):
        plots["foot_skate"] = "plots/foot_skate.png"
    if plot_phrasings(data, out / "plots" / "phrasings.png"):
        plots["phrasings"] = "plots/phrasings.png"
    mode = "post" if "post" in data["meta"]["modes"] else data["meta"]["modes"][0]
    for case in pick_filmstrip_cases(results.cases, filmstrips):
        motion = results.motions.get(case["id"], {}).get(mode)
        if motion is None:
            continue
        rel = f"plots/filmstrip_{case['id']}.png"
        title = f"{case['id']} ({mode}): {case['prompt'] or '(no text)'}"
        render_filmstrip(motion, out / rel, frames=6, targets=_render_targets(case), title=title[:90])
        plots["filmstrips"].append(rel)
    data["plots"] = plots
    atomic_write_bytes(out / "report.json", (json.dumps(data, indent=1, allow_nan=False) + "\n").encode("utf-8"))
    atomic_write_bytes(out / "report.md", _markdown(data).encode("utf-8"))
    return data
