"""Everything in examples/ runs as shipped, on the shipped default model, and gives plausible motion.

* every constraints file (examples/constraints/*.json) with a prompt that fits it, post-processing on:
  finite, the pelvis never faster than 10 m/s, no warnings (but the guard's floor note), every target
  met (the post-processing report's residuals after it);
* every timeline (examples/timelines/*.json): its length, finite, plausible;
* every numbered script (examples/NN_*.py) run as ``__main__`` in a scratch folder: it writes what it
  says it wrote, and prints no warning.

The constraints files and the scripts run with the model's own sampling settings (fewer steps hid a
target that the model's 50 steps miss); the timelines with 10 DDIM steps.
"""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import pytest
import torch

import kinema

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
CONSTRAINT_FILES = sorted((EXAMPLES / "constraints").glob("*.json"))
TIMELINES = sorted((EXAMPLES / "timelines").glob("*.json"))
OBJECTIVE_FILES = sorted((EXAMPLES / "objectives").glob("*.json"))
STREAM_SCRIPTS = sorted((EXAMPLES / "streams").rglob("*.jsonl"))  # played in tests/test_stream.py,
#: streams/creatures/ in tests/test_stream_anyrig.py
SCRIPTS = sorted(EXAMPLES.glob("[0-9][0-9]_*.py"))

#: a prompt that fits each constraints file (a file asking for a walk's path gets a walk, ...)
PROMPTS = {
    "dense_path": "A person walks forward.",
    "waypoints": "A person walks forward.",
    "hands": "A person raises their right hand.",
    # it lifts the left ankle 40 cm at 3.5 s 0.6 m ahead: with the stop-28 default "A person raises their
    # left leg." steps back and leaves that target 51 / 22 cm out of reach at seeds 0 / 1 (the previous
    # default met it), "A person stands still." is an unknown prompt; this one meets it at seeds 0-3
    "feet_contacts": "A person raises their left foot.",
    "inbetween_from_bvh": "A person walks forward.",
}
SECONDS = 5.0  # the files' keyframes go up to 4.9 s
STEPS = 10  # timelines (the constraints files run with the model's own steps, as `kinema generate` does)
MAX_PELVIS_SPEED = 10.0  # m/s, frame to frame: far above a sprint, catches jumps and blow-ups
#: largest residual after post-processing, per kind of target (cm, or degrees for rotations); a dense
#: path is blended onto (measured max 2.3 cm), the other targets are met to round-off
MAX_RESIDUAL = 5.0


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


def pelvis_speed(motion) -> torch.Tensor:
    """Frame-to-frame speed of joint 0's global position, m/s, (T - 1,)."""
    p = motion.positions[:, 0]
    return (p[1:] - p[:-1]).norm(dim=-1) * motion.fps


def check_plausible(motion, label: str) -> None:
    assert motion.is_finite(), f"{label}: non-finite values"
    assert torch.isfinite(motion.positions).all(), f"{label}: non-finite joint positions"
    speed = pelvis_speed(motion)
    worst, top = int(speed.argmax()), float(speed.max())
    assert top < MAX_PELVIS_SPEED, f"{label}: pelvis moves at {top:.1f} m/s between frames {worst} and {worst + 1}"


def test_every_example_file_is_tested():
    """A new file in examples/ needs a prompt here (or a place in one of the lists)."""
    assert {p.stem for p in CONSTRAINT_FILES} == set(PROMPTS)
    assert TIMELINES and SCRIPTS
    assert OBJECTIVE_FILES
    covered = set(CONSTRAINT_FILES) | set(TIMELINES) | set(SCRIPTS) | set(OBJECTIVE_FILES) | set(STREAM_SCRIPTS)
    files = {p for p in EXAMPLES.rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert files <= covered, f"untested files in examples/: {sorted(map(str, files - covered))}"


@pytest.mark.parametrize("path", CONSTRAINT_FILES, ids=lambda p: p.stem)
def test_constraints_example(path, model, bandai_workdir, monkeypatch):
    # inbetween_from_bvh.json names its clip as ../shared/datasets/... from the repository: run from a
    # folder where that is the Bandai Namco data (the real one, else the synthetic one)
    monkeypatch.chdir(bandai_workdir)
    # (the synthetic clip's bones point elsewhere at rest than Bandai's: kinema.constraints.retarget aligns them)
    result = model.generate(PROMPTS[path.stem], seconds=SECONDS, constraints=path, seed=0)
    check_constraints_result(result, path.name, round(SECONDS * model.fps))


@pytest.mark.parametrize("path", OBJECTIVE_FILES, ids=lambda p: p.stem)
def test_objectives_example_reads_and_binds(path, model, bandai_workdir, monkeypatch):
    """Each examples/objectives file binds its objectives (and its explicit constraints) to the shipped
    model's skeleton for the 5-s motion its comment asks for; generating with them is tested in
    tests/test_objectives_generate.py (hand-to-head, goal reach, time-agnostic path)."""
    from kinema.constraints import load_constraints
    from kinema.human.objective_sampling import collect_objectives

    monkeypatch.chdir(bandai_workdir)  # goal_reach.json names a Bandai Namco clip relative to the repository
    frames = round(SECONDS * model.fps)
    bound = collect_objectives(path, None, model.skeleton, model.fps, frames)
    assert bound, f"{path.name}: no objectives"
    data = json.loads(path.read_text())
    assert set(data) <= {"comment", "fps", "constraints", "objectives"}
    load_constraints(path, model.skeleton, model.fps, frames)


def check_constraints_result(result, label: str, frames: int) -> None:
    motion = result[0]
    assert motion.num_frames == frames
    exact = result.report.residuals[0]["exact"]
    print(label, json.dumps({"before": exact["before"], "after": exact["after"]}), result.report.warnings)
    check_plausible(motion, label)
    # the only warning allowed: the guard saying the exact pass put a foot below the floor (issue 36;
    # hands.json: Toes_R 3.1 cm, kept because the hand targets need the pass), and never more than 5 cm
    others = [w for w in result.report.warnings if "below the floor" not in w]
    assert others == []
    assert float(motion.positions[..., 1].min()) > -0.05, label
    assert exact["unmet"] == []
    assert exact["after"], f"{label}: no residuals measured"
    for name, res in exact["after"].items():
        assert res["count"] > 0
        assert res["max"] < MAX_RESIDUAL, f"{label}: {name} missed by up to {res['max']:.2f} after post-processing"


@pytest.fixture(scope="module")
def timelines(model):
    """Each timeline example generated once (short sampling): {path: (segments, result)}."""
    out = {}
    for path in TIMELINES:
        segments = json.loads(path.read_text())
        out[path] = segments, model.generate(path, steps=STEPS, seed=0)
    return out


@pytest.mark.parametrize("path", TIMELINES, ids=lambda p: p.stem)
def test_timeline_example(path, model, timelines):
    segments, result = timelines[path]
    motion = result[0]
    seconds = sum(s["seconds"] for s in segments)
    assert motion.num_frames == round(seconds * model.fps)
    assert result.report.segments == len(segments)
    check_plausible(motion, path.name)
    # the only warnings: the caption-fidelity table's, for a wave (a raised hand that does not swing; the
    # examples' comments say so)
    assert all("does not reliably make 'wave-" in w for w in result.report.warnings), result.report.warnings


def _segment_measures(motion, bow: slice, wave: slice, walk: slice) -> dict[str, float]:
    """Trunk lean (pelvis -> head from vertical) in the bow, right hand over the head in the wave, mean
    pelvis speed in the walk and in the bow's last 3 s (a bow stands still)."""
    names = list(motion.skeleton.names)
    p = motion.positions
    up = p[:, names.index("Head")] - p[:, 0]
    lean = torch.rad2deg(torch.acos(up[:, 1] / up.norm(dim=-1)))
    hand_over_head = p[:, names.index("Hand_R"), 1] - p[:, names.index("Head"), 1]
    speed = pelvis_speed(motion)
    found = {"bow: max lean (deg)": float(lean[bow].max()),
             "bow: mean pelvis speed, last 3 s (m/s)": float(speed[bow][-int(3 * motion.fps) :].mean()),
             "wave: max right hand over head (m)": float(hand_over_head[wave].max()),
             "walk: mean pelvis speed (m/s)": float(speed[walk].mean())}
    print(found)
    return found


def test_bow_wave_walk_follows_each_prompt(model, timelines):
    """examples/timelines/bow_wave_walk.json: a bow (trunk leans forward), then a raised right hand
    (above the head), then a walk (the pelvis travels). Before issue 18's joins (10 frames imposed as
    constraints, w_constr 2) the wave stayed below the head and the walk crept at 0.2-0.3 m/s."""
    path = EXAMPLES / "timelines/bow_wave_walk.json"
    fps = model.fps
    motion = timelines[path][1][0]
    found = _segment_measures(motion, slice(0, int(3 * fps)), slice(int(3 * fps), int(6 * fps)),
                              slice(int(6.5 * fps), None))
    assert found["bow: max lean (deg)"] > 15
    assert found["wave: max right hand over head (m)"] > 0.1
    assert found["walk: mean pelvis speed (m/s)"] > 0.5


def _walk_bow_wave(model, timelines) -> dict[str, float]:
    fps = model.fps
    motion = timelines[EXAMPLES / "timelines/walk_bow_wave.json"][1][0]
    return _segment_measures(motion, slice(int(4 * fps), int(8 * fps)), slice(int(8 * fps), None),
                             slice(0, int(4 * fps)))


def test_walk_bow_wave_follows_each_prompt(model, timelines):
    """Issue 18's timeline: the walk travels, then the person stops (the bow segment stands still) and
    the wave raises the right hand above the head. Before the fix the walk went on through all 12 s
    (bow segment 1.0-1.4 m/s) and the hand stayed 0.3-0.4 m below the head."""
    found = _walk_bow_wave(model, timelines)
    assert found["walk: mean pelvis speed (m/s)"] > 0.8
    assert found["bow: mean pelvis speed, last 3 s (m/s)"] < 0.5
    assert found["wave: max right hand over head (m)"] > 0.1


def test_walk_bow_wave_bow_leans_25_degrees(model, timelines):
    """Issue 18: after a walk, the bow segment's trunk leans forward at least 25 degrees (pelvis -> head).
    The captures bow 26-72 deg. Before the stop-28 default (a fine-tune with the text projection trained in
    whitened caption coordinates, its model card) this bow leaned 11 deg at seed 0 and the test was an
    expected failure; these weights lean 29, 20, 35, 37 deg at seeds 0-3 (10 steps, as here)."""
    assert _walk_bow_wave(model, timelines)["bow: max lean (deg)"] >= 25


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_example_script(script, tmp_path, monkeypatch, capsys):
    """Run as ``python examples/NN_name.py`` would, from an empty folder."""
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    print(out)
    written = [line.split()[1].rstrip(":") for line in out.splitlines() if line.startswith("wrote ")]
    assert written, f"{script.name} printed no 'wrote FILE' line"
    for name in written:
        path = tmp_path / name
        assert path.is_file() and path.resolve().is_relative_to((tmp_path / "out").resolve()), f"{script.name}: {name}"
        check_plausible(kinema.load_motion(path), f"{script.name}: {name}")
    # no warning but the caption-fidelity table's for a wave (03_timeline's, whose timeline says waves are weak)
    warned = [line for line in out.lower().splitlines() if "warning" in line]
    assert all("does not reliably make 'wave-" in line for line in warned), warned
