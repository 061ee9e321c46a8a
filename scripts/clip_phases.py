"""Which locomotion captures start or end at rest, and how much of each is steady (kinema.data.phases).

    python scripts/clip_phases.py cache/bandai20p [--split train]

Per content of a dataset build (source clips, not mirrors): clips, how many have a steady stretch, start at
rest, end at rest, the median clip and steady lengths (s) and the steady speed's 20/50/80 % quantiles (m/s).
"""

from __future__ import annotations

import argparse
import statistics
from collections import defaultdict

from kinema.data.dataset import MotionDataset
from kinema.data.phases import LOCOMOTION, clip_phases


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="a `kinema data build` folder")
    ap.add_argument("--split", default="train")
    args = ap.parse_args()
    ds = MotionDataset(args.data, args.split)
    rows = defaultdict(list)
    for rec in ds.clips:
        if rec["content"] not in LOCOMOTION or rec["mirrored"]:
            continue
        rows[rec["content"]].append((rec["duration_s"], clip_phases(ds, rec)))
    print("content     clips steady starts ends  clip_s steady_s  steady m/s q20/50/80")
    for content, clips in sorted(rows.items()):
        phased = [p for _, p in clips if p is not None]
        speeds = sorted(p.steady_speed for p in phased)
        q = [speeds[int(f * (len(speeds) - 1))] for f in (0.2, 0.5, 0.8)] if speeds else [0, 0, 0]
        steady = statistics.median((p.steady_end - p.steady_start) / ds.fps for p in phased) if phased else 0.0
        print(f"{content:11s} {len(clips):5d} {len(phased):6d} {sum(p.starts_at_rest for p in phased):6d} "
              f"{sum(p.ends_at_rest for p in phased):4d}  {statistics.median(d for d, _ in clips):6.2f} {steady:8.2f}  "
              + " / ".join(f"{x:.2f}" for x in q))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
