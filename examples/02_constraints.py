"""Text + constraints: walk through the ground waypoints of examples/constraints/waypoints.json.

    python examples/02_constraints.py     # writes out/02_waypoints.bvh under the current folder

The waypoints are at 1.5, 3.0, 4.5 and 4.9 s, so the motion lasts 5 s (a keyframe past the end is an
error). Post-processing (on by default) moves the motion onto the targets exactly; the report says how
far they were missed before and after it. The constraint format: docs/constraints.md.
"""

from __future__ import annotations

import os
from pathlib import Path

import kinema

CONSTRAINTS = Path(__file__).resolve().parent / "constraints" / "waypoints.json"


def main() -> None:
    model = kinema.load_model()
    result = model.generate("A person walks forward.", seconds=5, constraints=CONSTRAINTS, seed=0)
    motion = result[0]
    path = motion.save("out/02_waypoints.bvh")
    print(f"wrote {path}: {motion.num_frames} frames at {motion.fps:g} fps ({motion.duration:.1f} s)")
    exact = result.report.residuals[0]["exact"]  # per-sample post-processing report
    for name, before in exact["before"].items():
        after = exact["after"][name]
        print(f"  {name}: max {before['max']:.2f} before post-processing, {after['max']:.2f} after "
              f"({before['count']} targets)")
    for warning in result.report.warnings:
        print(f"warning: {warning}")
    shown = os.path.relpath(CONSTRAINTS) if CONSTRAINTS.is_relative_to(Path.cwd()) else CONSTRAINTS
    print(f"see it: kinema render {path} --out out/02_waypoints.png --constraints {shown}")


if __name__ == "__main__":
    main()
