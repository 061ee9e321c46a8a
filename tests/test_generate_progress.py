"""``generate(..., progress=fn)``: real step counts for progress bars, never a different result."""

from __future__ import annotations

import pytest
import torch

from kinema.diffusion.sampler import DDIMSampler
from kinema.errors import KinemaError
from kinema.generate import load_model
from kinema.pipeline.progress import StepProgress


@pytest.fixture(scope="module")
def model(tiny_checkpoint):
    return load_model(tiny_checkpoint)


def _same(a, b) -> bool:
    return torch.equal(a.local_rotations, b.local_rotations) and torch.equal(a.root_translation, b.root_translation)


def test_callback_counts_steps_and_changes_nothing(model):
    timeline = [("A person walks forward.", 1.0), ("A person waves.", 1.0)]
    args = dict(samples=2, steps=5, seed=3, postprocess=False)
    plain = model.generate(timeline, **args)
    calls: list[tuple[int, int]] = []
    counted = model.generate(timeline, progress=lambda done, total: calls.append((done, total)), **args)
    assert all(_same(a, b) for a, b in zip(plain, counted, strict=True))
    assert counted.report.segments == 2
    total = 5 + 5 + 3  # two segments of 5 steps, then the join's window: the last 60 % of them
    assert [d for d, _ in calls] == list(range(1, total + 1))
    assert {t for _, t in calls} == {total}


def test_chunked_segments_advance_monotonically():
    calls: list[tuple[int, int]] = []
    counter = StepProgress(lambda d, t: calls.append((d, t)), steps=[4, 4])
    for k in range(2):
        on_step = counter.segment(k)
        for done in range(1, 13):  # three chunks of 4 steps each
            on_step(done, 12)
    done = [d for d, _ in calls]
    assert done == sorted(set(done)) and done[-1] == 8 and {t for _, t in calls} == {8}
    assert done[:4] == [1, 2, 3, 4]


def test_sampler_calls_on_step_after_every_step():
    sampler = DDIMSampler(num_inference_steps=6)
    calls: list[tuple[int, int]] = []
    x = sampler.sample(
        lambda x, t: x * 0.5,
        (2, 3, 4),
        generator=torch.Generator().manual_seed(0),
        on_step=lambda d, n: calls.append((d, n)),
    )
    y = sampler.sample(lambda x, t: x * 0.5, (2, 3, 4), generator=torch.Generator().manual_seed(0))
    assert torch.equal(x, y)
    assert calls == [(i, 6) for i in range(1, 7)]


def test_bad_progress_is_a_clear_error(model):
    with pytest.raises(KinemaError, match="progress must be True, False or a callable"):
        model.generate("A person walks.", seconds=1.0, steps=2, progress="yes")
