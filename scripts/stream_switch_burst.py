"""Root speed around a prompt switch in a stream (docs/stream.md, "Prompt switches: no burst").

For walk -> jog, wave -> jog and walk -> bow at seeds 0 and 1: 4 s of the first prompt, the switch,
3 s of the second, on one thread at the stream's 10 steps. Prints the pelvis speed before the switch,
its peak in the 1.5 s after it (pelvis ground speed under a 0.1-s Gaussian), the largest change of that
speed around the switch (and before it), and the largest trunk lean after it.

    python scripts/stream_switch_burst.py                  # the stream as it is (guidance 4, root from a first pass)
    python scripts/stream_switch_burst.py --guidance 2 2   # another switch guidance
    python scripts/stream_switch_burst.py --no-first-pass  # guidance 4 alone (before the fix)
"""

from __future__ import annotations

import argparse

import torch

import kinema.stream.continuation as continuation
from kinema.generate import load_model
from kinema.motion.smoothing import smooth_time
from kinema.pipeline.request import GenerationRequest
from kinema.stream import open_stream
from kinema.stream.measure import frames_to_motion, trunk_lean_deg

SWITCHES = (("A person walks forward.", "A person jogs."), ("A person waves with the right hand.", "A person jogs."),
            ("A person walks forward.", "A person bows."))
BEFORE, AFTER = 80, 60


def measure(model, first: str, second: str, seed: int) -> tuple[float, float, float, float, float]:
    s = open_stream(model, GenerationRequest(prompt=first, seed=seed))
    a = s.next_frames(BEFORE)
    s.set_prompt(second)
    b = s.next_frames(AFTER)
    m = frames_to_motion([a, b], model.skeleton)
    p = m.root_translation[:, [0, 2]].float()
    speed = smooth_time(((p[1:] - p[:-1]).norm(dim=-1) * m.fps)[:, None], 0.1 * m.fps)[:, 0]
    change = (speed[1:] - speed[:-1]).abs() * m.fps
    return (float(speed[BEFORE - 20 : BEFORE].mean()), float(speed[BEFORE : BEFORE + 30].max()),
            float(change[BEFORE - 5 : BEFORE + 30].max()), float(change[: BEFORE - 5].max()),
            float(trunk_lean_deg(m)[BEFORE:].max()))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--guidance", type=float, nargs=2, default=list(continuation.SWITCH_GUIDANCE))
    ap.add_argument("--no-first-pass", action="store_true", help="no root path from a first pass")
    args = ap.parse_args()
    torch.set_num_threads(1)
    continuation.SWITCH_GUIDANCE = tuple(args.guidance)
    continuation.ROOT_FROM_FIRST_PASS = not args.no_first_pass
    model = load_model("default")
    for first, second in SWITCHES:
        rows = [measure(model, first, second, seed) for seed in (0, 1)]
        print(f"{first} -> {second} guidance {tuple(args.guidance)}: " + " | ".join(
            f"seed {k}: before {r[0]:.2f} m/s, peak {r[1]:.2f} m/s, speed change {r[2]:.0f} m/s^2 (before "
            f"{r[3]:.0f}), lean {r[4]:.0f} deg" for k, r in enumerate(rows)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
