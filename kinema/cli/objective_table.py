"""The objective table `kinema generate` prints after a call with objectives (``report.objectives``)."""

from __future__ import annotations

UNITS = {"realism": "m/s^2"}


def objective_table(report: dict) -> str:
    """Rows ``sample, objective, before, optimised, snapped (raw), final`` per objective and sample ("" without).

    Values: cm (realism: RMS joint acceleration, m/s^2). ``before``: the motion the unoptimised noise
    gives; ``optimised``: after noise optimisation; ``snapped (raw)``: the raw output after snapping
    (kinema.objectives.snap); ``final``: after post-processing."""
    if not report or not report.get("objectives"):
        return ""
    rows = []
    for k, o in enumerate(report["objectives"]):
        unit = UNITS.get(o["type"], "cm")
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
