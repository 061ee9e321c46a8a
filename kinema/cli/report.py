"""How `kinema generate` shows a generation report: which training captions each prompt was grounded
on, a short table of constraint residuals (cm, degrees), the objectives' table, the robot's replay and
the warnings, on stderr, that a user must not miss."""

from __future__ import annotations

import sys
import warnings

#: residual key -> (what it measures, unit)
KINDS = {
    "full_body_position_cm": ("keyframe joint positions", "cm"),
    "full_body_rotation_deg": ("keyframe joint rotations", "deg"),
    "position_cm": ("joint position targets", "cm"),
    "rotation_deg": ("joint rotation targets", "deg"),
    "root_xz_cm": ("root path / waypoints", "cm"),
    "contact_skate_cm_s": ("planted-foot skate", "cm/s"),
}


def residual_table(residuals: list[dict]) -> str:
    """Rows ``sample, constraint, raw max, mean, max`` for every post-processed sample that had
    constraints (``report.residuals``); "" when no sample had any."""
    rows = []
    for i, rep in enumerate(residuals):
        exact = rep.get("exact") if rep else None
        if not exact:
            continue
        for key, (what, unit) in KINDS.items():
            after, before = exact["after"].get(key), exact["before"].get(key)
            if after is None:
                continue
            raw = f"{before['max']:.2f} {unit}" if before else "-"
            rows.append((str(i), what, raw, f"{after['mean']:.2f} {unit}", f"{after['max']:.2f} {unit}",
                         str(after["count"])))
    if not rows:
        return ""
    head = ("sample", "constraint", "raw max", "mean", "max", "count")
    widths = [max(len(r[k]) for r in [head, *rows]) for k in range(len(head))]
    lines = ["constraint residuals after post-processing (raw max: the model's own output):"]
    for r in [head, *rows]:
        lines.append("  " + "  ".join(c.ljust(w) if k < 2 else c.rjust(w) for k, (c, w) in
                                      enumerate(zip(r, widths, strict=True))))
    return "\n".join(lines)


def prompt_lines(prompts: list[dict]) -> list[str]:
    """How the prompts of ``report.prompts`` were conditioned: per grounded prompt, the training captions
    it was blended with and their weights (kinema.model.grounding); per prompt that the model's action
    expert made, a line saying so (kinema.model.action_expert), and one per prompt made as the mirror image
    of its other side's (kinema.human.mirrored_request)."""
    lines = []
    for p in prompts:
        made = p.get("made_as_mirror_of", p["prompt"])
        if made != p["prompt"]:
            lines.append(f"made {p['prompt']!r} as the mirror image of {made!r} (the model makes that side better; "
                         "kinema.human.mirrored_request)")
        g = p.get("grounding") or {}
        if g.get("status") == "grounded":
            caps = ", ".join(f"{c['caption']!r} ({c['weight']:.2f})" for c in g["captions"])
            lines.append(f"grounded {made!r} (own weight {g['prompt_weight']:.2f}) on {caps}")
        if p.get("weights") == "action expert":
            lines.append(f"made {made!r} with the model's action expert")
    return lines


def print_warnings(messages: list[str]) -> None:
    """Each warning once, as ``kinema: warning: ...`` on stderr."""
    for msg in dict.fromkeys(messages):
        print(f"kinema: warning: {msg}", file=sys.stderr)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"kinema: warning: {message}", file=sys.stderr if file is None else file)


def use_plain_warnings() -> None:
    """Python warnings raised while a command runs (e.g. a constraint file read at another fps) print as
    one ``kinema: warning:`` line instead of Python's file:line format."""
    warnings.showwarning = _show_warning


#: objective type -> its unit in the objective table (cm otherwise)
OBJECTIVE_UNITS = {"realism": "m/s^2"}


def objective_table(report: dict) -> str:
    """Rows ``sample, objective, before, optimised, snapped (raw), final`` per objective and sample ("" without).

    Values: cm (realism: RMS joint acceleration, m/s^2). ``before``: the motion the unoptimised noise
    gives; ``optimised``: after noise optimisation; ``snapped (raw)``: the raw output after snapping
    (kinema.objectives.snap); ``final``: after post-processing."""
    if not report or not report.get("objectives"):
        return ""
    rows = []
    for k, o in enumerate(report["objectives"]):
        unit = OBJECTIVE_UNITS.get(o["type"], "cm")
        scale = 1.0 if unit != "cm" else 100.0
        n = len(o["before"])
        for i in range(n):
            vals = [o.get(key, [None] * n)[i] for key in ("before", "optimised", "after", "final")]
            cells = ("-" if v is None else f"{v * scale:.2f} {unit}" for v in vals)
            rows.append((str(i), f"{k}: {o['type']}", *cells))
    head = ("sample", "objective", "before", "optimised", "snapped (raw)", "final")
    widths = [max(len(r[c]) for r in [head, *rows]) for c in range(len(head))]
    lines = [
        f"objectives ({report['iterations']} noise iterations, {report['ddim_steps']} DDIM steps, "
        f"{report['seconds']:.1f} s):"
    ]
    for r in [head, *rows]:
        lines.append(
            "  "
            + "  ".join(c.ljust(w) if j < 2 else c.rjust(w) for j, (c, w) in enumerate(zip(r, widths, strict=True)))
        )
    return "\n".join(lines)


def guidance_words(mode: str, weights) -> str:
    """``", regular guidance 2"`` / ``", separated guidance 2 / 2"`` for the summary line ("" without a mode)."""
    if mode == "regular":
        return f", regular guidance {weights[0]:g}"
    if mode == "separated":
        return f", separated guidance {weights[0]:g} / {weights[1]:g}"
    return ""


def print_report(result) -> None:
    """What `kinema generate` prints after writing the files, for any pipeline: the summary line, the
    grounding lines, the residual and objective tables, the constraint errors and the warnings (stderr)."""
    rep = result.report
    where = f" on {rep.joints} joints" if rep.joints else ""
    windows = f", {rep.windows} window(s)" if rep.windows > 1 else ""
    print(f"generated {len(result)} motion(s){where}, {rep.segments} segment(s){windows}, {rep.steps} DDIM steps"
          f"{guidance_words(rep.guidance_mode, rep.guidance)} in {rep.seconds:.2f} s")
    for line in prompt_lines(rep.prompts):
        print(line)
    for table in (residual_table(rep.residuals), objective_table(rep.objectives)):
        if table:
            print(table)
    if rep.residuals_cm:
        print(f"constraint error after post-processing: max {max(rep.residuals_cm):.2f} cm")
    if rep.residuals_deg:
        print(f"rotation target error after post-processing: max {max(rep.residuals_deg):.2f} deg")
    for i, c in enumerate(rep.character):
        print(f"sample {i} on {c['character']}: size x{c['scale']:.2f}, limb directions within "
              f"{c['direction_deg_mean']:.1f} deg on average ({c['direction_deg_max']:.1f} at most), lowest joint "
              f"{c['lowest']:.3g} (rest {c['lowest_rest']:.3g}, the character's units)"
              + (f", planted feet {c['ankle_cm']:.1f} cm above their rest height (source {c['ankle_source_cm']:.1f})"
                 if "ankle_cm" in c else "")
              + "".join(f", target on {name} {err:.2f} cm" for name, err in c["targets_cm"].items()))
    if rep.robot:
        from kinema.robot.stage import replay_words  # MuJoCo is loaded already: the robot stage ran

    for i, r in enumerate(rep.robot):
        print(f"sample {i} on {r['robot']} (replayed in MuJoCo): {replay_words(r)}")
        print(f"sample {i} dynamics (MuJoCo inverse dynamics): {r['dynamics_summary']}")
    print_warnings([*rep.left_out, *rep.warnings])
