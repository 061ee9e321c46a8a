"""The objective table `kinema generate` prints after a call with objectives (``report.objectives``)."""

from __future__ import annotations

UNITS = {"realism": "m/s^2"}


def objective_table(report: dict) -> str:
    """Rows ``sample, objective, before, after (raw), final`` for every objective and sample; "" without any.

    Values: metres (realism: RMS joint acceleration, m/s^2). ``before`` is the motion the unoptimised
    noise gives, ``after`` the optimised raw output, ``final`` the same after post-processing."""
    if not report or not report.get("objectives"):
        return ""
    rows = []
    for k, o in enumerate(report["objectives"]):
        unit = UNITS.get(o["type"], "cm")
        scale = 1.0 if unit != "cm" else 100.0
        for i, (b, a) in enumerate(zip(o["before"], o["after"], strict=True)):
            final = o.get("final", [None] * len(o["before"]))[i]
            rows.append(
                (
                    str(i),
                    f"{k}: {o['type']}",
                    f"{b * scale:.2f} {unit}",
                    f"{a * scale:.2f} {unit}",
                    "-" if final is None else f"{final * scale:.2f} {unit}",
                )
            )
    head = ("sample", "objective", "before", "after (raw)", "final")
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
