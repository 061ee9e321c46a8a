"""Does a human model make a kick from the text, or only copy it from its noisy input? (issue 38)

    python scripts/kick_denoising_probe.py --data cache/bandai20h --models default runs/h38g/ckpt-00001000

For the first (unmirrored) kick-left train clip of ``--data``, normalised with each model's statistics and
noised to each step t (one noise draw per step, seed 0), the model's x0 prediction with the clip's first
caption and with no text; printed: the left foot's highest point above the hips in that prediction
(metres; the clip's own value last). A model that only copies the kick from its input lifts the foot at
low t and not at high t, with or without the text (docs/training.md, "Stop 50"). A run's checkpoint folder
loads its EMA weights; for the raw ones, `kinema export CKPT --weights raw --out DIR` and pass DIR.
"""

from __future__ import annotations

import argparse

import torch

STEPS = (100, 300, 600, 900, 960, 980, 990, 999)


def foot_over_hips(rep, features: torch.Tensor, names: list[str]) -> float:
    P = rep.to_motion(features).positions
    return float((P[:, names.index("Foot_L"), 1] - P[:, names.index("Hips"), 1]).max())


def main() -> int:
    import kinema
    from kinema.data.dataset import MotionDataset

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True,
                    help="a build with kick-left clips (kinema data build quaternius-humanoids)")
    ap.add_argument("--models", nargs="+", default=["default"])
    args = ap.parse_args()
    torch.set_num_threads(1)
    ds = MotionDataset(args.data, split="train")
    picks = [i for i, r in enumerate(ds.clips) if r.get("content") == "kick-left" and not r.get("mirrored")]
    if not picks:
        raise SystemExit(f"{args.data}: no unmirrored kick-left train clip")
    item = ds[picks[0]]
    for name in args.models:
        model = kinema.load_model(name, precision="fp32")
        L = model.loaded
        names = list(L.skeleton.names)
        x0 = ((item["features"] - L.stats.mean) / L.stats.std)[None]
        text = model.encode_text(item["captions"][0])
        g = torch.Generator().manual_seed(0)
        cells = []
        for step in STEPS:
            t = torch.tensor([step])
            x_t = L.sampler.schedule.q_sample(x0, t, torch.randn(x0.shape, generator=g))
            with torch.no_grad():
                pair = [L.denoiser(x_t, t, e)[0] * L.stats.std + L.stats.mean for e in (text, None)]
            cells.append(f"t={step}: {foot_over_hips(L.representation, pair[0], names):+.2f} / "
                         f"{foot_over_hips(L.representation, pair[1], names):+.2f}")
        print(f"{name} (text / no text): " + ", ".join(cells))
    clip = foot_over_hips(L.representation, item["features"], names)
    print(f"the clip itself: {clip:+.2f} m ({item['captions'][0]!r})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
