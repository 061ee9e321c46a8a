"""A timeline: several prompts in sequence (bow, wave, walk; 10 s) from examples/timelines/bow_wave_walk.json.

    python examples/03_timeline.py        # writes out/03_bow_wave_walk.bvh under the current folder

A timeline is a JSON list of {"prompt", "seconds"} segments (a "comment" key, or any key starting with
"_", is ignored); a Python list of such dicts or of (prompt, seconds) pairs works too. Each segment
continues from the previous one's last frames. The same from the command line:
``kinema generate --timeline examples/timelines/bow_wave_walk.json --out out/03_bow_wave_walk.bvh``.
"""

from __future__ import annotations

from pathlib import Path

import kinema

TIMELINE = Path(__file__).resolve().parent / "timelines" / "bow_wave_walk.json"


def main() -> None:
    model = kinema.load_model()
    result = model.generate(TIMELINE, seed=0)  # a timeline sets its own length: no seconds=
    motion = result[0]
    path = motion.save("out/03_bow_wave_walk.bvh")
    print(f"wrote {path}: {motion.num_frames} frames at {motion.fps:g} fps ({motion.duration:.1f} s, "
          f"{result.report.segments} segments)")
    for warning in result.report.warnings:
        print(f"warning: {warning}")


if __name__ == "__main__":
    main()
