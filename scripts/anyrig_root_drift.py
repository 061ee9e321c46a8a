"""Where an any-rig idle's drift comes from (issue 34): the root's forward speed in the denoiser's x0
prediction, along the sampling chain and on the rig's own clip noised to a few levels.

    python scripts/anyrig_root_drift.py --model creatures --data cache/quat20rm --file Fox --content idle

For the first clip of ``--content`` on the file's skeleton (build units: body sizes): (1) the clip's own
forward speed and the x0 prediction's mean over the window when the clip is noised to t = 999 ... 50
(4 noise draws each, its first caption as the prompt) -- a bias here is the denoiser's; (2) one
generation of 4 s from that caption (post-processing off), the x0 prediction's mean forward speed at
every DDIM step -- what the sampling chain adds up. Speeds in body sizes/s.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

import kinema.anyrig.sampling as sampling
from kinema.data.motion_cache import MotionCache
from kinema.diffusion.schedule import NoiseSchedule
from kinema.generate import load_model
from kinema.model.skeleton_codes import batch_codes, skeleton_codes
from kinema.representation.joint import ROOT_FORWARD, JointRepresentation
from kinema.rig import Rig


def noised_bias(pipe, motion, rig: Rig, caption: str, levels=(999, 800, 500, 200, 50)) -> dict[int, float]:
    loaded = pipe.loaded
    den = loaded.denoiser.eval()
    feats = JointRepresentation(rig, loaded.fps).from_motion(motion).float()[: loaded.config.window]
    codes = batch_codes([skeleton_codes(rig, loaded.config)])
    x0 = den.normalize(feats[None], codes)
    text = pipe.text_encoder.encode([caption]).float()
    frames = torch.ones(1, x0.shape[1], dtype=torch.bool)
    schedule, out = NoiseSchedule(), {}
    for t in levels:
        gen, got = torch.Generator().manual_seed(0), []
        for _ in range(4):
            x_t = schedule.q_sample(x0, torch.tensor([t]), torch.randn(x0.shape, generator=gen))
            with torch.no_grad():
                pred = den(x_t, torch.tensor([t]), text, codes, frames, torch.zeros_like(x0), torch.zeros_like(x0))
            got.append(float(den.denormalize(pred, codes)[0, :, rig.root, ROOT_FORWARD].mean()))
        out[t] = sum(got) / len(got)
    return out


def chain(pipe, rig: Rig, caption: str, steps: int, seed: int) -> list[tuple[int, float]]:
    den, log = pipe.loaded.denoiser, []
    call = sampling.WindowDenoiser.__call__

    def spy(self, x_t, t):
        x0 = call(self, x_t, t)
        log.append((t, float(den.denormalize(x0, self.codes)[0, :, rig.root, ROOT_FORWARD].mean())))
        return x0

    sampling.WindowDenoiser.__call__ = spy
    try:
        pipe.generate(caption, rig=rig, seconds=4, steps=steps, seed=seed, postprocess=False)
    finally:
        sampling.WindowDenoiser.__call__ = call
    return log


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", default="creatures")
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--file", required=True, help="source file stem, e.g. Fox")
    p.add_argument("--content", default="idle")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    pipe, cache = load_model(a.model), MotionCache(a.data)
    idx = [i for i, r in enumerate(cache.clips) if Path(r["skeleton"]).stem == a.file and r["content"] == a.content]
    if not idx:
        p.error(f"{a.data}: no {a.content!r} clip on a skeleton named {a.file!r}")
    motion = cache.motion(idx[0])
    rig, caption = Rig.from_skeleton(motion.skeleton), cache.clips[idx[0]]["captions"][0]
    own = JointRepresentation(rig, pipe.loaded.fps).from_motion(motion)[:, rig.root, ROOT_FORWARD].mean()
    print(f"{caption!r} ({cache.clips[idx[0]]['split']}): own forward speed {float(own):+.3f}")
    bias = noised_bias(pipe, motion, rig, caption)
    print("x0 on the noised clip: " + "  ".join(f"t{t} {v:+.3f}" for t, v in bias.items()))
    along = chain(pipe, rig, caption, a.steps, a.seed)
    print("x0 along the sampling chain: " + "  ".join(f"t{t} {v:+.3f}" for t, v in along))
    return 0


if __name__ == "__main__":
    sys.exit(main())
