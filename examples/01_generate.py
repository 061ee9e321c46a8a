"""Text only: a 4-s walk from a prompt, with the default model that ships inside kinema.

    python examples/01_generate.py        # writes out/01_walk.bvh under the current folder

The same as ``kinema generate "A person walks forward happily." --seconds 4 --out out/01_walk.bvh``.
Look at it with ``kinema render out/01_walk.bvh --out out/01_walk.png`` (or import the BVH into Blender).
"""

from __future__ import annotations

import kinema


def main() -> None:
    model = kinema.load_model()  # the shipped default; or kinema.load_model("runs/NAME")
    result = model.generate("A person walks forward happily.", seconds=4, seed=0)
    motion = result[0]
    path = motion.save("out/01_walk.bvh")  # metres, Y up; .npz works too
    print(f"wrote {path}: {motion.num_frames} frames at {motion.fps:g} fps ({motion.duration:.1f} s)")
    for warning in result.report.warnings:
        print(f"warning: {warning}")


if __name__ == "__main__":
    main()
