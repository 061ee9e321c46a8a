"""How well does a human model denoise one clip of each content? (issue 38: is a fine-tune learning the
new actions?)

    python scripts/content_denoising_loss.py --data cache/bandai20h --models default runs/h38d/ckpt-00002000 \
        --contents kick-left jump punch-right roll walk

For the first train clip of each content (not mirrored where there is a choice; its first 80 frames),
normalised with each model's own statistics: the mean squared error of the model's x0 prediction from
x_t at diffusion steps 100, 300 and 600 (three noise draws each, seed 0), conditioned on the clip's
first caption; and the largest |x0| channel value, in standard deviations of the model's statistics
(far outside the captures' range, the denoiser has to learn outputs it never made). Lower is better; a
content the model reproduces well sits near the captures' own (walk ~0.06). A run's checkpoint folder
loads its EMA weights; to measure the raw ones, `kinema export CKPT --weights raw --out DIR` and pass DIR.
"""

from __future__ import annotations

import argparse

import torch

STEPS = (100, 300, 600)
DRAWS = 3
FRAMES = 80


def first_clips(ds, contents: list[str]) -> list[tuple[str, torch.Tensor, str]]:
    """(content, features (T, D), caption) of the first train clip of each content, unmirrored first."""
    out = []
    for content in contents:
        recs = [i for i, r in enumerate(ds.clips) if r.get("content") == content]
        if not recs:
            raise SystemExit(f"{ds.dir}: no train clip of content {content!r}")
        recs.sort(key=lambda i: bool(ds.clips[i].get("mirrored")))
        item = ds[recs[0]]
        out.append((content, item["features"][:FRAMES], item["captions"][0]))
    return out


def denoising_loss(model, features: torch.Tensor, caption: str) -> tuple[float, float]:
    """(mean x0 MSE in normalised units, largest |normalised value|) of one clip under ``model``."""
    loaded = model.loaded
    x0 = ((features - loaded.stats.mean) / loaded.stats.std)[None]
    text = model.encode_text(caption)
    g = torch.Generator().manual_seed(0)
    errors = []
    for step in STEPS:
        t = torch.tensor([step])
        for _ in range(DRAWS):
            noise = torch.randn(x0.shape, generator=g)
            with torch.no_grad():
                pred = loaded.denoiser(loaded.sampler.schedule.q_sample(x0, t, noise), t, text)
            errors.append(float(((pred - x0) ** 2).mean()))
    return sum(errors) / len(errors), float(x0.abs().max())


def main() -> int:
    import kinema
    from kinema.data.dataset import MotionDataset

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="a human dataset build (kinema data build)")
    ap.add_argument("--models", nargs="+", default=["default"], help="model names or run/checkpoint folders")
    ap.add_argument("--contents", nargs="+", default=["kick-left", "jump", "punch-right", "roll", "walk"])
    args = ap.parse_args()
    torch.set_num_threads(1)
    clips = first_clips(MotionDataset(args.data, "train"), args.contents)
    print("| model | " + " | ".join(c for c, _, _ in clips) + " |")
    print("|---|" + "---:|" * len(clips))
    for name in args.models:
        model = kinema.load_model(name, precision="fp32")
        cells = []
        for _content, features, caption in clips:
            loss, peak = denoising_loss(model, features, caption)
            cells.append(f"{loss:.3f} (max {peak:.0f} std)")
        print(f"| {name} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
