"""Action experts (kinema.model.action_expert): a model folder with a second set of weights that denoises the
prompts naming its actions; every other prompt runs on the model's own weights, as before."""

from __future__ import annotations

import json

import pytest
import torch

from kinema.cli import main
from kinema.constraints.types import EndEffectorConstraint, FullBodyConstraint, Root2DConstraint
from kinema.errors import KinemaError
from kinema.generate import load_model
from kinema.geometry.rotations import axis_angle_to_quat, quat_to_axis_angle
from kinema.human.mirrored_request import mirror_constraints
from kinema.model.loading import load_denoiser
from kinema.model.sides import mirror_caption

KICK, WALK = "A person kicks with the left leg.", "A person walks forward."


def _positions(model, prompt, **kw):
    res = model.generate(prompt, seconds=1.0, seed=5, steps=4, postprocess=False, **kw)
    return res[0].positions, res.report


@pytest.fixture(scope="module")
def routed(tiny_checkpoint, tiny_data, tmp_path_factory):
    """(routed folder, main folder, expert folder): the tiny run's EMA weights as the main network, its raw
    weights (they differ) as the expert for kicks and jumps."""
    tmp = tmp_path_factory.mktemp("experts")
    main_dir, expert_dir, routed_dir = tmp / "main", tmp / "expert", tmp / "routed"
    assert main(["export", str(tiny_checkpoint), "--out", str(main_dir), "--dtype", "float32", "--known-prompts",
                 str(tiny_data)]) == 0
    assert main(["export", str(tiny_checkpoint), "--out", str(expert_dir), "--dtype", "float32",
                 "--weights", "raw"]) == 0
    assert main(["export", str(main_dir), "--out", str(routed_dir), "--dtype", "float32", "--known-prompts",
                 str(tiny_data), "--action-expert", str(expert_dir), "--expert-actions", "kick", "jump"]) == 0
    return routed_dir, main_dir, expert_dir


@pytest.fixture(scope="module")
def mirroring(routed, tiny_data, tmp_path_factory):
    """The routed folder with its expert making right-side prompts as mirror images (--expert-mirror-side)."""
    routed_dir, main_dir, expert_dir = routed
    out = tmp_path_factory.mktemp("mirroring") / "model"
    assert main(["export", str(main_dir), "--out", str(out), "--dtype", "float32", "--known-prompts",
                 str(tiny_data), "--action-expert", str(expert_dir), "--expert-actions", "kick", "jump",
                 "--expert-mirror-side", "right"]) == 0
    return out


def _copy_with_expert_entry(folder, out, entry):
    """A copy of the model ``folder`` at ``out`` whose checkpoint.json has ``entry`` as its action expert."""
    out.mkdir()
    for f in folder.iterdir():
        (out / f.name).write_bytes(f.read_bytes())
    info = json.loads((folder / "checkpoint.json").read_text())
    (out / "checkpoint.json").write_text(json.dumps(info | {"action_expert": entry}))
    return out


def test_prompts_naming_an_expert_action_run_on_the_expert_weights(routed) -> None:
    """A kick prompt gives exactly what the expert's own folder gives, a walk prompt what the main folder
    gives, and the two networks do differ; the report says which weights served each prompt."""
    routed_dir, main_dir, expert_dir = routed
    model, alone_main, alone_expert = load_model(routed_dir), load_model(main_dir), load_model(expert_dir)
    kick, report = _positions(model, KICK)
    assert torch.allclose(kick, _positions(alone_expert, KICK)[0], atol=1e-6)
    assert not torch.allclose(kick, _positions(alone_main, KICK)[0], atol=1e-3)
    assert report.prompts[0]["weights"] == "action expert"
    walk, report = _positions(model, WALK)
    assert torch.allclose(walk, _positions(alone_main, WALK)[0], atol=1e-6)
    assert report.prompts[0]["weights"] == "main"
    assert "weights" not in _positions(alone_main, WALK)[1].prompts[0]  # a model without an expert says nothing
    timeline = model.generate([(WALK, 1.0), (KICK, 1.0)], seed=5, steps=4, postprocess=False)
    assert [p["weights"] for p in timeline.report.prompts] == ["main", "action expert"]
    info = json.loads((routed_dir / "checkpoint.json").read_text())["action_expert"]
    assert info["actions"] == ["jump", "kick"] and info["weights"] == "action_expert.safetensors"


def test_bad_experts_are_refused_with_one_line(routed, tmp_path, capsys) -> None:
    """An expert of another network, an unknown action or one flag without the other is a one-line error that
    writes nothing; a folder whose expert entry or weights are damaged does not load."""
    routed_dir, main_dir, expert_dir = routed
    out = tmp_path / "x"
    assert main(["export", str(main_dir), "--out", str(out), "--action-expert", "default",
                 "--expert-actions", "kick"]) == 2
    assert "another model_config" in capsys.readouterr().err
    assert main(["export", str(main_dir), "--out", str(out), "--action-expert", str(expert_dir),
                 "--expert-actions", "moonwalk"]) == 2
    assert "unknown actions ['moonwalk']" in capsys.readouterr().err
    assert main(["export", str(main_dir), "--out", str(out), "--action-expert", str(expert_dir)]) == 2
    assert "go together" in capsys.readouterr().err
    assert not out.exists()
    info = json.loads((routed_dir / "checkpoint.json").read_text())
    broken = _copy_with_expert_entry(routed_dir, tmp_path / "broken", {"actions": "kick"})
    with pytest.raises(KinemaError, match="field 'action_expert': expected an object with a list 'actions'"):
        load_denoiser(broken)
    (broken / "checkpoint.json").write_text(json.dumps(info))
    (broken / "action_expert.safetensors").write_bytes(b"garbage")
    with pytest.raises(KinemaError, match="action_expert.safetensors: not a readable safetensors"):
        load_denoiser(broken)


def test_an_expert_prompt_naming_the_mirror_side_is_made_as_the_mirror_image(mirroring) -> None:
    """Issue 38: with ``mirror_side`` "right", a right kick is the left kick made at the mirrored heading and
    mirrored back (raw output: exactly); a timeline with an unsided walk is mirrored whole; the report says
    what each prompt was made as. Requests that would not map onto themselves are made as they are: the
    left kick, a prompt naming both sides and a right-hand prompt the expert does not serve."""
    model = load_model(mirroring)
    assert json.loads((mirroring / "checkpoint.json").read_text())["action_expert"]["mirror_side"] == "right"
    right = model.generate(mirror_caption(KICK), seconds=1.0, seed=5, steps=4, postprocess=False, heading=0.4)
    left = model.generate(KICK, seconds=1.0, seed=5, steps=4, postprocess=False, heading=-0.4)
    assert torch.allclose(right[0].positions, left[0].mirror().positions, atol=1e-5)
    assert right.report.prompts[0]["made_as_mirror_of"] == KICK and right.report.prompts[0]["prompt"] != KICK
    assert right.report.prompts[0]["grounding"] == left.report.prompts[0]["grounding"]
    timeline = model.generate([(WALK, 1.0), (mirror_caption(KICK), 1.0)], seed=5, steps=4, postprocess=False)
    assert [p["made_as_mirror_of"] for p in timeline.report.prompts] == [WALK, KICK]
    for prompt in (KICK, "A person kicks with the left leg, then the right leg.", "A person raises the right hand."):
        assert "made_as_mirror_of" not in _positions(model, prompt)[1].prompts[0], prompt


def test_constraints_are_sampled_mirrored_and_hit_in_the_users_frame(mirroring) -> None:
    """A constrained right kick samples the mirror images of its constraints (the left kick with mirrored
    constraints, at the negated heading, mirrored back: the same raw motion), and post-processing puts the
    user's own targets on the output: the right hand and the root waypoint where the user put them."""
    model = load_model(mirroring)
    user = [{"type": "root2d", "frame_indices": [19], "smooth_root_2d": [[0.3, 0.6]],
             "global_root_heading": [[0.8, 0.6]]},
            {"type": "end-effector", "joint": "right_hand", "frame_indices": [10], "positions": [[-0.3, 1.1, 0.3]]},
            {"type": "foot-contact", "frame_indices": [0], "contacts": [[1, 1, 0, 0]]}]
    mirrored = [{"type": "root2d", "frame_indices": [19], "smooth_root_2d": [[-0.3, 0.6]],
                 "global_root_heading": [[0.8, -0.6]]},
                {"type": "end-effector", "joint": "Hand_L", "frame_indices": [10], "positions": [[0.3, 1.1, 0.3]]},
                {"type": "foot-contact", "frame_indices": [0], "contacts": [[0, 0, 1, 1]]}]
    kw = {"seconds": 1.0, "seed": 5, "steps": 4, "keyjoint_model": "none"}
    right = model.generate(mirror_caption(KICK), constraints=user, postprocess=False, heading=0.4, **kw)
    left = model.generate(KICK, constraints=mirrored, postprocess=False, heading=-0.4, **kw)
    assert right.report.prompts[0]["made_as_mirror_of"] == KICK
    assert torch.allclose(right[0].positions, left[0].mirror().positions, atol=1e-5)
    post = model.generate(mirror_caption(KICK), constraints=user, **kw)
    names = list(post[0].skeleton.names)
    hand = post[0].positions[10, names.index("Hand_R")]
    assert torch.allclose(hand, torch.tensor([-0.3, 1.1, 0.3]), atol=0.02), hand
    after = post.report.residuals[0]["exact"]["after"]  # measured on the output, against the user's targets
    assert after["position_cm"]["max"] < 0.1 and after["root_xz_cm"]["max"] < 0.1, after
    assert post.report.prompts[0]["made_as_mirror_of"] == KICK


def test_mirrored_constraints_are_the_constraints_of_the_mirrored_motion(routed) -> None:
    """mirror_constraints on keyframe poses, a hand target (position and global rotation) and a path taken
    from a motion gives what the same read-out of the motion's mirror image gives."""
    motion = load_model(routed[1]).generate(WALK, seconds=1.0, seed=1, steps=4, postprocess=False)[0]
    frames = [0, 12]

    def read_out(m):
        names = list(m.skeleton.names)
        return [FullBodyConstraint(frame_indices=frames, local_rotations=quat_to_axis_angle(m.local_rotations[frames]),
                                   root_positions=m.root_translation[frames]),
                EndEffectorConstraint(frame_indices=frames, joint="Hand_L",
                                      positions=m.positions[frames, names.index("Hand_L")],
                                      rotations=quat_to_axis_angle(m.global_rotations[frames, names.index("Hand_L")])),
                Root2DConstraint(frame_indices=frames, positions=m.root_translation[frames][:, [0, 2]])]

    ours, theirs = mirror_constraints(read_out(motion), motion.skeleton), read_out(motion.mirror())
    assert ours[1].joint == "Hand_R"
    mirrored, right = motion.mirror(), list(motion.skeleton.names).index("Hand_R")
    theirs[1] = EndEffectorConstraint(frame_indices=frames, joint="Hand_R", positions=mirrored.positions[frames, right],
                                      rotations=quat_to_axis_angle(mirrored.global_rotations[frames, right]))
    for a, b in ((ours[0].local_rotations, theirs[0].local_rotations), (ours[1].rotations, theirs[1].rotations)):
        dots = (axis_angle_to_quat(a) * axis_angle_to_quat(b)).sum(-1)
        assert float(dots.abs().min()) > 1 - 1e-5  # the same rotations (q and -q are one)
    assert torch.allclose(ours[0].root_positions, theirs[0].root_positions, atol=1e-5)
    assert torch.allclose(ours[1].positions, theirs[1].positions, atol=1e-5)
    assert torch.allclose(ours[2].positions, theirs[2].positions, atol=1e-5)


def test_a_bad_mirror_side_is_refused_with_one_line(routed, tmp_path, capsys) -> None:
    """--expert-mirror-side takes left or right and needs --action-expert; a folder whose entry names another
    side does not load."""
    routed_dir, main_dir, expert_dir = routed
    out = tmp_path / "x"
    assert main(["export", str(main_dir), "--out", str(out), "--expert-mirror-side", "right"]) == 2
    assert "give --action-expert RUN too" in capsys.readouterr().err
    assert not out.exists()
    entry = json.loads((routed_dir / "checkpoint.json").read_text())["action_expert"] | {"mirror_side": "up"}
    broken = _copy_with_expert_entry(routed_dir, tmp_path / "broken", entry)
    with pytest.raises(KinemaError, match="mirror_side must be one of left, right, got 'up'"):
        load_denoiser(broken)
