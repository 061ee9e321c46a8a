"""`kinema.render` and `kinema render`: real Bandai clips drawn to PNG filmstrips and GIFs.

Checks are on the pixels that come out (valid image, not blank, the side colours, contact and target
markers present) rather than on matplotlib internals, so the drawing style can change freely.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image, ImageSequence

from kinema.cli import main
from kinema.errors import KinemaError
from kinema.io import load_motion
from kinema.motion.contacts import foot_contacts
from kinema.motion.core import Motion
from kinema.render import CONTACT_COLOUR, SIDE_COLOURS, TARGET_COLOUR, render_filmstrip, render_gif
from kinema.skeleton import Skeleton


@pytest.fixture(scope="module")
def walk(walk_clip) -> Motion:
    """The first 3 s of the Bandai walk (real, or the synthetic one of the same name: see conftest.py)."""
    return load_motion(walk_clip, scale=0.01).crop(0, 90)


def _rgb(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB")).astype(np.int16)


def _has_colour(img: np.ndarray, hex_colour: str, min_pixels: int = 20, tol: int = 40) -> bool:
    target = np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(img - target).max(-1) < tol).sum()) >= min_pixels


def test_filmstrip_is_a_readable_non_blank_png(walk, tmp_path):
    out = render_filmstrip(walk, tmp_path / "strip.png", frames=6, title="walk")
    assert out == tmp_path / "strip.png"
    with Image.open(out) as im:
        assert im.format == "PNG"
        w, h = im.size
    assert 600 < w < 4000 and 200 < h < 800 and w > 2 * h  # six panels side by side
    img = _rgb(out)
    assert img.std() > 10  # not blank
    assert _has_colour(img, SIDE_COLOURS["L"]) and _has_colour(img, SIDE_COLOURS["R"])
    assert [p.name for p in tmp_path.iterdir()] == ["strip.png"]  # no temp file left behind


def test_gif_has_frames_that_move(walk, tmp_path):
    out = render_gif(walk.crop(0, 45), tmp_path / "anim.gif", fps=10, title="walk")
    with Image.open(out) as im:
        assert im.format == "GIF"
        frames = [np.asarray(f.convert("RGB")).astype(np.int16) for f in ImageSequence.Iterator(im)]
    assert len(frames) == 15  # 1.5 s at 10 fps
    assert frames[0].std() > 10
    assert np.abs(frames[0] - frames[-1]).mean() > 0.5


def test_targets_and_contacts_are_drawn(walk, tmp_path):
    contacts = foot_contacts(walk.positions, walk.fps, walk.skeleton)
    marked = Motion(walk.skeleton, walk.fps, walk.root_translation, walk.local_rotations, contacts)
    hand = walk.positions[45, walk.skeleton.index("left_hand")].numpy() + [0.0, 0.15, 0.1]
    root = walk.positions[60, walk.skeleton.index("pelvis")].numpy()
    targets = [(45, hand, "left hand"), (60, (root[0], root[2]), "waypoint"), (None, hand + [0, 0.2, 0])]
    plain = _rgb(render_filmstrip(walk, tmp_path / "plain.png", frames=3))
    drawn = _rgb(render_filmstrip(marked, tmp_path / "drawn.png", frames=3, targets=targets))
    assert plain.shape == drawn.shape and np.abs(plain - drawn).mean() > 0.1
    assert _has_colour(drawn, TARGET_COLOUR) and not _has_colour(plain, TARGET_COLOUR)
    assert _has_colour(drawn, CONTACT_COLOUR) and not _has_colour(plain, CONTACT_COLOUR)
    gif = render_gif(marked.crop(40, 50), tmp_path / "t.gif", targets=[(5, hand, "h")])
    assert gif.stat().st_size > 0


@pytest.mark.parametrize(
    "bad", [[(5, (1.0, 2.0, 3.0, 4.0))], [(500, (0, 1, 0))], [(1, (np.nan, 0, 0))], [(1,)], [(1.5, (0, 1, 0))]]
)
def test_bad_targets_raise(walk, tmp_path, bad):
    with pytest.raises(KinemaError):
        render_filmstrip(walk, tmp_path / "x.png", frames=2, targets=bad)
    assert not (tmp_path / "x.png").exists()


def test_bad_outputs_raise(walk, tmp_path):
    with pytest.raises(KinemaError, match=".png"):
        render_filmstrip(walk, tmp_path / "x.jpg")
    with pytest.raises(KinemaError, match=".gif"):
        render_gif(walk, tmp_path / "x.png")
    with pytest.raises(KinemaError):
        render_filmstrip(walk, tmp_path / "x.png", frames=0)
    with pytest.raises(KinemaError):
        render_gif(walk, tmp_path / "x.gif", fps=-1)
    assert list(tmp_path.iterdir()) == []


def test_any_rig_renders_without_roles(tmp_path):
    """Joints with no recognisable names: no head, no facing, no sides; still drawn, single frame too."""
    skel = Skeleton(["a", "b", "c", "d"], [-1, 0, 1, 1], [[0, 1, 0], [0, 0.5, 0], [0.3, 0.2, 0], [-0.3, 0.2, 0]])
    T = 5
    quats = torch.zeros(T, 4, 4)
    quats[..., 0] = 1
    root = torch.stack([torch.linspace(0, 0.5, T), torch.ones(T), torch.zeros(T)], -1)
    motion = Motion(skel, 30, root, quats)
    assert _rgb(render_filmstrip(motion, tmp_path / "a.png", frames=4)).std() > 5
    assert render_filmstrip(motion.crop(0, 1), tmp_path / "one.png", frames=8).exists()
    assert render_gif(motion, tmp_path / "a.gif").exists()


def test_cli_renders_png_and_gif(walk_clip, tmp_path, capsys):
    png, gif = tmp_path / "s.png", tmp_path / "a.gif"
    assert main(["render", str(walk_clip), "--scale", "0.01", "--out", str(png), "--frames", "4", "--title", "t"]) == 0
    assert "wrote" in capsys.readouterr().out
    npz = tmp_path / "c.npz"
    load_motion(walk_clip, scale=0.01).crop(0, 30).save(npz)
    assert main(["render", str(npz), "--out", str(gif), "--fps", "10"]) == 0
    with Image.open(png) as a, Image.open(gif) as b:
        assert a.format == "PNG" and b.format == "GIF" and b.n_frames == 10


def test_cli_marks_constraints(walk_clip, tmp_path):
    pytest.importorskip("kinema.constraints")
    motion = load_motion(walk_clip, scale=0.01)
    hand = motion.positions[60, motion.skeleton.index("right_hand")].tolist()
    pelvis = motion.positions[[30, 90], motion.skeleton.index("pelvis")]
    spec = [
        {"type": "right-hand", "times": [2.0], "positions": [[hand[0], hand[1] + 0.2, hand[2]]]},
        {"type": "root2d", "frame_indices": [30, 90], "smooth_root_2d": pelvis[:, [0, 2]].tolist()},
        {"type": "foot-contact", "times": [0.5], "contacts": [[1, 1, 0, 0]]},
    ]
    cfile = tmp_path / "c.json"
    cfile.write_text(json.dumps(spec))
    png = tmp_path / "c.png"
    args = [
        "render",
        str(walk_clip),
        "--scale",
        "0.01",
        "--out",
        str(png),
        "--frames",
        "4",
        "--constraints",
        str(cfile),
    ]
    assert main(args) == 0
    assert _has_colour(_rgb(png), TARGET_COLOUR)
    spec[0]["times"] = [60.0]  # beyond the clip: a one-line error
    cfile.write_text(json.dumps(spec))
    assert main(args) == 2


def test_cli_bad_input_exits_2(walk_clip, tmp_path, capsys):
    empty = tmp_path / "empty.bvh"
    empty.write_bytes(b"")
    odd = tmp_path / "motion.txt"
    odd.write_text("hello")
    garbage = tmp_path / "bad.bvh.gz"
    garbage.write_bytes(b"\x1f\x8b\x08not really gzip")
    npz = tmp_path / "c.npz"
    load_motion(walk_clip, scale=0.01).crop(0, 5).save(npz)
    out = str(tmp_path / "o.png")
    cases = [
        [str(tmp_path / "missing.bvh"), "--out", out],
        [str(empty), "--out", out],
        [str(odd), "--out", out],
        [str(garbage), "--out", out],
        [str(walk_clip), "--scale", "0.01", "--out", str(tmp_path / "o.jpg")],
        [str(npz), "--scale", "0.01", "--out", out],
        [str(walk_clip), "--scale", "0.01", "--out", out, "--constraints", str(odd)],
        [str(walk_clip), "--scale", "0.01", "--out", out, "--fps", "10"],
    ]
    for args in cases:
        assert main(["render", *args]) == 2, args
        err = capsys.readouterr().err
        assert err.startswith("kinema: error:") and err.count("\n") == 1, err
    assert not (tmp_path / "o.png").exists()
