"""Long prompts as continuation (kinema/human/continuation.py): a prompt longer than its action's captures is
made window by window and keeps going (issue 57)."""

from __future__ import annotations

import pytest
import torch

import kinema
from kinema.errors import KinemaError
from kinema.human.continuation import CAPTURE_SHARE, continuation_window
from kinema.model.vocabulary import KnownPrompts, median_seconds, median_speeds
from kinema.pipeline.request import GenerationRequest
from kinema.text import get_text_encoder

RUN = "A man runs quickly down the road."


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


def speed(motion, t0: float, t1: float) -> float:
    xz = motion.root_translation[:, [0, 2]].double()
    a, b = round(t0 * motion.fps), round(t1 * motion.fps)
    return float((xz[a + 1 : b + 1] - xz[a:b]).norm(dim=-1).sum()) / (t1 - t0)


def test_window_comes_from_the_captures_of_the_grounded_caption(model):
    request = GenerationRequest(prompt=RUN, seconds=10)
    window = continuation_window(model, request, 10.0)
    run_captures = model.known_prompts.seconds_of("A man runs straight ahead.")
    assert run_captures == pytest.approx(3.15)
    assert window == pytest.approx(CAPTURE_SHARE * run_captures, abs=0.5 / model.fps)
    assert continuation_window(model, request, 2.0) is None  # within the captures: one window
    walk = GenerationRequest(prompt="A person walks ahead.", seconds=5)
    assert continuation_window(model, walk, 5.0) is None  # walks were captured for 7.85 s
    timeline = GenerationRequest(timeline=[{"prompt": RUN, "seconds": 10}])
    assert continuation_window(model, timeline, 10.0) is None
    hand = {"constraints": [{"type": "end-effector", "joint_names": ["RightHand"], "frame_indices": [10],
                             "positions": [[0.3, 1.5, 0.4]]}]}
    assert continuation_window(model, GenerationRequest(prompt=RUN, seconds=10, constraints=hand), 10.0) is None


def test_a_long_run_keeps_running_and_is_reproducible(model):
    result = model.generate(RUN, seconds=7, seed=1, steps=10)
    motion = result[0]
    assert motion.num_frames == 140
    assert motion.foot_contacts is not None and tuple(motion.foot_contacts.shape) == (140, 4)  # evaluators read them
    early, late = speed(motion, 1, 3), speed(motion, 4.9, 6.9)
    assert early > 1.8 and late >= 0.75 * early, (early, late)
    made = result.report.prompts[0]["continued"]
    assert made["windows"] >= 3 and made["window_seconds"] == pytest.approx(CAPTURE_SHARE * 3.15, abs=0.05)
    # kept at the speed the captures of its caption travel at, from the first window on
    assert made["speed_from"] == "captures" and made["speed"] == pytest.approx(2.69, abs=0.01)
    assert early == pytest.approx(made["speed"], rel=0.15) and late == pytest.approx(made["speed"], rel=0.15)
    again = model.generate(RUN, seconds=7, seed=1, steps=10)[0]
    assert torch.equal(again.root_translation, motion.root_translation)
    two = model.generate(RUN, seconds=7, seed=1, steps=10, samples=2)
    assert len(two.motions) == 2 and torch.equal(two[0].root_translation, motion.root_translation)
    assert not torch.equal(two[1].root_translation, motion.root_translation)


def test_caption_seconds_are_saved_and_checked(tmp_path):
    enc = get_text_encoder("hash-test-32")
    clips = [["A person runs."], ["A person runs.", "A person bows."], ["A person bows."]]
    known = KnownPrompts.from_clips(clips, enc, clip_seconds=[3.0, 5.0, 2.0])
    assert known.seconds_of("A person runs.") == 4.0 and known.seconds_of("A person bows.") == 3.5
    assert known.seconds_of("A person waves.") is None
    known.save(tmp_path)
    assert KnownPrompts.load(tmp_path).caption_seconds == known.caption_seconds
    with pytest.raises(KinemaError, match="no clip carries"):
        median_seconds(["A person waves."], clips, [1.0, 2.0, 3.0])
    with pytest.raises(KinemaError, match="one positive length per caption"):
        KnownPrompts(known.captions, known.embeddings, known.encoder_id, caption_seconds=[1.0])


def test_caption_speeds_are_the_median_of_the_travelling_clips(tmp_path):
    enc = get_text_encoder("hash-test-32")
    clips = [["A person runs."], ["A person runs.", "A person bows."], ["A person bows."], ["A person runs."]]
    known = KnownPrompts.from_clips(clips, enc, clip_seconds=[3.0, 5.0, 2.0, 1.0], clip_speeds=[2.0, None, None, 3.0])
    assert known.speed_of("A person runs.") == 2.5  # the clip that does not travel is left out
    assert known.speed_of("A person bows.") is None and known.speed_of("A person waves.") is None
    known.save(tmp_path)
    assert KnownPrompts.load(tmp_path).caption_speeds == known.caption_speeds
    with pytest.raises(KinemaError, match="4 clips but 3 clip speeds"):
        median_speeds(known.captions, clips, [1.0, 2.0, 3.0])
    with pytest.raises(KinemaError, match="one speed"):
        KnownPrompts(known.captions, known.embeddings, known.encoder_id, caption_speeds=[1.0, float("nan")])


def test_bench_lengths_reports_cost_per_second_of_motion(model):
    from kinema.bench.lengths import bench_lengths, format_lengths

    rows = bench_lengths(model, durations=(2.0, 4.0), prompts=("A person runs forward.",))
    assert [(r.seconds, r.windows > 1) for r in rows] == [(2.0, False), (4.0, True)]
    assert all(r.wall_s > 0 and abs(r.per_second_s - r.wall_s / r.seconds) < 1e-9 for r in rows)
    assert "s per motion s" in format_lengths(rows)


def test_only_travel_is_continued(model):
    bow = GenerationRequest(prompt="A person bows deeply.", seconds=9)
    assert continuation_window(model, bow, 9.0) is None  # one bow, not one per window
    turn = GenerationRequest(prompt="A person walks forward and turns to the left.", seconds=9)
    assert continuation_window(model, turn, 9.0) is None


def test_a_long_run_in_a_timeline_keeps_running(model):
    timeline = [{"prompt": "A person walks forward.", "seconds": 2}, {"prompt": RUN, "seconds": 6}]
    result = model.generate(timeline, seed=0, steps=10)
    motion = result[0]
    assert result.report.segments == 1 + 3  # the run in pieces of at most 0.75 x its 3.15-s captures
    assert speed(motion, 5.9, 7.9) > 1.8, speed(motion, 5.9, 7.9)


def test_a_stream_sizes_its_windows_by_the_prompt_and_a_stroll_is_slower_than_a_jog(model):
    stream = model.stream(GenerationRequest(prompt="A person walks at an easy pace.", seed=0))
    walk = stream.next_frames(200)
    stream.set_prompt("A person jogs forward.")
    jog = stream.next_frames(200)
    fps = model.fps
    assert stream.settings.window_for(model, "A person walks at an easy pace.") == round(
        model.window_for("A person walks at an easy pace.") * fps)
    assert model.window_for("A person jogs forward.") < model.window_for("A person walks at an easy pace.")

    def mean_speed(frames):
        xz = frames.root_translation[80:, [0, 2]].double()
        return float((xz[1:] - xz[:-1]).norm(dim=-1).sum()) * fps / (xz.shape[0] - 1)

    assert mean_speed(walk) + 0.5 < mean_speed(jog), (mean_speed(walk), mean_speed(jog))
