"""Issue 34's size question: the any-rig denoiser at 0.3 M against ~2 M parameters, trained from scratch for
the same CPU time on the same data (one thread each), then measured on the held-out files:

    python scripts/anyrig_size_compare.py --out runs/size34 --minutes 20 --data cache/quat20rm
    python scripts/anyrig_gait_check.py --model runs/size34/small ...   # and runs/size34/large

Each run is a plain `AnyRigTrainer` (kinema.train.anyrig.trainer) stopped by ``--minutes``; its step count
is set from a short timing so the cosine learning-rate schedule ends near the time limit. Run the two sizes
in two processes at once (``--only small`` / ``--only large``) so they share the machine alike.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from kinema.model.anyrig.config import get_anyrig_config
from kinema.runtime import configure_threads
from kinema.train.anyrig.trainer import AnyRigTrainConfig, AnyRigTrainer

SIZES = {"small": {}, "large": {"width": 128, "layers": 5, "heads": 8}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--data", default="cache/quat20rm")
    p.add_argument("--minutes", type=float, default=20.0)
    p.add_argument("--only", choices=sorted(SIZES), required=True)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    configure_threads(1, cap=None)
    cfg = get_anyrig_config("anyrig-small", **SIZES[args.only])
    out = args.out / args.only
    probe = AnyRigTrainer(cfg, AnyRigTrainConfig(steps=10, seed=args.seed), args.data, out / "probe", log=print)
    t0 = time.time()
    for _ in range(6):
        probe.train_step()
    per_step = (time.time() - t0) / 6
    steps = max(50, int(args.minutes * 60 / per_step))
    print(f"{args.only}: {probe.model.num_parameters()} parameters, {per_step:.2f} s/step -> {steps} steps", flush=True)
    del probe
    trainer = AnyRigTrainer(cfg, AnyRigTrainConfig(steps=steps, seed=args.seed, ckpt_every=max(50, steps // 4)),
                            args.data, out, log=lambda s: print(s, flush=True))
    trainer.run(minutes=args.minutes)


if __name__ == "__main__":
    main()
