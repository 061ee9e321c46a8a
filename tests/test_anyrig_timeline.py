"""Timelines for any-rig models: windows per segment, each with its segment's prompt, cross-faded over
the frames a segment re-plays of the previous one (kinema.anyrig.windows), through the sampler,
the Python API and ``kinema generate --timeline``."""

from __future__ import annotations

import json
from types import SimpleNamespace

import creature_fixtures
import pytest
import torch
from rig_fixtures import fish, quadruped

import kinema
from kinema.anyrig.sampling import sample_features
from kinema.anyrig.windows import segment_overlap, segment_plan, single_plan, window_weights
from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.errors import KinemaError
from kinema.model.anyrig.config import get_anyrig_config
from kinema.model.skeleton_codes import batch_codes, skeleton_codes
from kinema.pipeline.request import GenerationRequest
from kinema.rig import Rig

creature_cache, trained = creature_fixtures.creature_cache, creature_fixtures.trained  # module-scoped fixtures


def test_segment_plan_places_windows_and_crossfades_the_shared_frames() -> None:
    plan = segment_plan([0, 30, 60], 16, 4)
    assert plan.frames == 60 and plan.width == 16
    assert set(plan.prompts) == {0, 1}
    for s, n, p in zip(plan.starts, plan.lengths, plan.prompts, strict=True):  # segment 1 starts 4 frames early
        assert (0 <= s and s + n <= 30) if p == 0 else (26 <= s and s + n <= 60)
    w, cover = plan.weights(), torch.zeros(60)
    for k, (s, n) in enumerate(zip(plan.starts, plan.lengths, strict=True)):
        cover[s : s + n] += w[k, :n]
    assert cover.min() > 0
    last0 = max(k for k, p in enumerate(plan.prompts) if p == 0)
    first1 = plan.prompts.index(1)
    assert torch.allclose(w[last0, 12:16], torch.tensor([4, 3, 2, 1]) / 5)  # fades out over frames 26..29
    assert torch.allclose(w[first1, :4], torch.tensor([1, 2, 3, 4]) / 5)  # ... while segment 1 fades in
    short = segment_plan([0, 5, 40], 16, 4)  # a 5-frame segment gets one 5-frame window, padded to 16
    assert short.lengths[0] == 5 and short.frame_mask()[0].sum() == 5 and short.weights()[0, 5:].eq(0).all()
    assert torch.equal(single_plan(90, 40).weights(), window_weights(single_plan(90, 40).starts, 40, 90))
    assert segment_overlap(20.0, 40) == 10 and segment_overlap(20.0, 16) == 4 and segment_overlap(5.0, 40) == 2


class _TextEcho:
    """A stand-in denoiser whose x0 is the first number of each window's text embedding everywhere
    (records the frame masks it is given), to check which prompt each frame is denoised with."""

    def __init__(self) -> None:
        self.config = SimpleNamespace(window=16, text_dim=4, channels=13)
        self.frame_masks: list[torch.Tensor] = []

    def normalize(self, x, codes):
        return x

    def denormalize(self, x, codes):
        return x

    def __call__(self, x, t, text, codes, frame_mask, x_tgt, mask):
        self.frame_masks.append(frame_mask)
        return text[:, :1, None, None].expand_as(x).clone()


def test_every_frame_is_denoised_with_its_segments_prompt() -> None:
    echo, rig = _TextEcho(), Rig.from_skeleton(fish())
    codes = batch_codes([skeleton_codes(rig, get_anyrig_config("anyrig-tiny"))], max_hops=8)
    plan = segment_plan([0, 5, 40], 16, 4)
    text = torch.tensor([[1.0, 0, 0, 0], [3.0, 0, 0, 0]])
    out = sample_features(
        echo,
        codes,
        GenerationRequest(steps=2, samples=2, seed=0),
        plan=plan,
        text_emb=text,
        targets=None,
        sampler=DDIMSampler(),
        guidance=Guidance("regular", w_text=1.0),
    )
    v = out[0, :, 0, 0]
    assert (
        torch.equal(out[0], out[1]) and v[0] == 1.0 and torch.allclose(v[5:], torch.tensor(3.0))
    )  # prompt 1 from frame 5 on
    assert 1.0 < float(v[1]) < float(v[4]) < 3.0  # frames 1..4: segment 0 cross-fading into segment 1
    assert echo.frame_masks[0].shape == (2 * 2 * len(plan.starts), 16)  # branches x samples x windows
    assert int(echo.frame_masks[0][0].sum()) == 5  # the short window's padding is masked


def _displacement(m) -> torch.Tensor:
    """Mean joint displacement (m) from each frame to the next, ``(T - 1,)``."""
    P = m.positions
    return (P[1:] - P[:-1]).norm(dim=-1).mean(dim=-1)


def test_timeline_frames_prompts_and_joins(trained) -> None:
    model = creature_fixtures.tiny_model(trained)
    rig = Rig.from_skeleton(quadruped())
    a = [{"prompt": "A quadruped does a walk.", "seconds": 1.5}, {"prompt": "A quadruped does a sway.", "seconds": 1.0}]
    b = [a[0], {"prompt": "A fish does a walk.", "seconds": 1.0}]
    kw = dict(rig=rig, steps=4, seed=3, postprocess=False)
    ra, rb = model.generate(a, **kw), model.generate(b, **kw)
    ma, mb = ra[0], rb[0]
    assert ma.num_frames == 50 and ra.report.segments == 2 and ra.report.windows > 2
    change = (ma.positions - mb.positions).norm(dim=-1).mean(dim=-1)
    assert float(change[30:].mean()) > 1e-6  # the second prompt steers the second segment ...
    assert float(change[:10].mean()) < 0.25 * float(change[30:].mean())  # ... and hardly the start of the first
    d = _displacement(ma)
    join = d[30 - segment_overlap(20.0, 16) - 1 : 31]  # the shared frames and the step into segment 1
    assert float(join.max()) <= 3.0 * float(d.quantile(0.9)) + 1e-9
    same = model.generate([{"prompt": "A quadruped does a walk.", "seconds": 2.5}], **kw)
    alone = model.generate("A quadruped does a walk.", seconds=2.5, **kw)
    assert torch.allclose(same[0].positions, alone[0].positions)  # one segment = one prompt
    with pytest.raises(KinemaError, match="segment 1"):
        model.generate([a[0], {"prompt": "x", "seconds": -1}], rig=rig)


def test_cli_generates_a_timeline(trained, tmp_path, capsys) -> None:
    from kinema.cli import main

    timeline = tmp_path / "t.json"
    timeline.write_text(
        json.dumps([{"prompt": "A thing walks.", "seconds": 1.0}, {"prompt": "It sways.", "seconds": 0.5}])
    )
    out = tmp_path / "m.bvh"
    args = ["generate", "--model", str(trained), "--rig", "fish0", "--steps", "2", "--out", str(out)]
    assert main([*args, "--timeline", str(timeline)]) == 0
    printed = capsys.readouterr().out
    assert "30 frames" in printed and "2 segment(s)" in printed and out.exists()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps([{"promt": "x", "seconds": 1}]))
    assert main([*args, "--timeline", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.json: segment 0: unknown key 'promt'" in err and len(err.splitlines()) == 1
    assert main([*args, "--timeline", str(tmp_path / "none.json")]) == 2
    assert "no such timeline file" in capsys.readouterr().err


def test_shipped_model_follows_each_segments_prompt() -> None:
    """The shipped `creatures` model on a synthetic quadruped: changing the second prompt changes the
    second segment and leaves the start of the first almost as it was; the join is no bigger a step
    than the motion's own steps."""

    model = kinema.load_model("creatures")
    rig = Rig.from_skeleton(quadruped())
    walk = {"prompt": "A dog walks.", "seconds": 2.0}
    kw = dict(rig=rig, steps=8, seed=0, postprocess=False)
    ma = model.generate([walk, {"prompt": "A dog attacks.", "seconds": 1.5}], **kw)[0]
    mb = model.generate([walk, {"prompt": "A dog dies.", "seconds": 1.5}], **kw)[0]
    assert ma.num_frames == 70
    change = (ma.positions - mb.positions).norm(dim=-1).mean(dim=-1)
    assert float(change[:20].mean()) < 0.1 * float(change[45:].mean())
    for m in (ma, mb):
        d = _displacement(m)
        join = d[40 - segment_overlap(20.0, 40) - 1 : 41]
        assert float(join.max()) <= 3.0 * float(d.quantile(0.9))
