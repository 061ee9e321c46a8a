"""Issue 13, sections 3-4, the command line: output paths are checked before any work, bad numbers and
timeline keys are one-line errors (exit 2, nothing written), never a traceback.
Shared helpers: tests/hardening_fixtures.py; input files are tests/test_hardening.py."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from kinema.atomic_files import check_output_path
from kinema.cli import main
from kinema.errors import KinemaError
from tests import hardening_fixtures as fixtures
from tests.hardening_fixtures import FAST, one_line_error

bvh_file, no_model = fixtures.bvh_file, fixtures.no_model  # fixtures shared with the other hardening tests


# ---------------------------------------------------------------------------- output paths
def test_check_output_path(tmp_path):
    assert check_output_path(tmp_path / "new/deeper/x.bvh") == tmp_path / "new/deeper/x.bvh"
    assert not (tmp_path / "new").exists()  # only checked; the writer creates folders
    assert not list(tmp_path.iterdir())  # the write probe leaves nothing behind
    (tmp_path / "folder.bvh").mkdir()
    with pytest.raises(KinemaError, match="is a folder"):
        check_output_path(tmp_path / "folder.bvh")
    (tmp_path / "file").write_text("x")
    with pytest.raises(KinemaError, match="is a file, not a folder"):
        check_output_path(tmp_path / "file/sub/x.bvh")


def _unwritable_folder() -> Path | None:
    """A folder nobody can write to, root included (sysfs is read-only), or None."""
    import tempfile

    sys_dir = Path("/sys")
    if not sys_dir.is_dir():
        return None
    try:
        fd, probe = tempfile.mkstemp(dir=sys_dir)
    except OSError:
        return sys_dir
    import os

    os.close(fd)
    os.unlink(probe)
    return None


def _bad_outputs(tmp_path: Path, name: str) -> list[tuple[Path, str]]:
    (tmp_path / f"dir{name}").mkdir()
    (tmp_path / "plain").write_text("x")
    cases = [(tmp_path / f"dir{name}", "is a folder"), (tmp_path / "plain" / name, "not a folder")]
    ro = _unwritable_folder()
    if ro is not None:
        cases.append((ro / "kinema-test" / name, "cannot write"))
    return cases


def test_generate_checks_output_path_before_loading_the_model(tmp_path, capsys, no_model):
    for out, msg in _bad_outputs(tmp_path, "m.bvh"):
        assert main(["generate", "walk", *FAST, "--out", str(out)]) == 2, out
        one_line_error(capsys, msg)
    assert main(["generate", "walk", *FAST, "--samples", "2", "--out", str(tmp_path / "plain/m.npz")]) == 2
    one_line_error(capsys, "m_00.npz")


def test_convert_and_render_check_output_path_first(tmp_path, bvh_file, capsys, monkeypatch):
    import kinema.io as kio

    def boom(*a, **k):
        raise AssertionError("the input was read before the bad output was reported")

    monkeypatch.setattr(kio, "load_motion", boom)
    for out, msg in _bad_outputs(tmp_path, "m.npz"):
        assert main(["convert", str(bvh_file), str(out)]) == 2, out
        one_line_error(capsys, msg)
    for out, msg in _bad_outputs(tmp_path, "m.png"):
        assert main(["render", str(bvh_file), "--out", str(out)]) == 2, out
        one_line_error(capsys, msg)
    assert main(["convert", str(bvh_file), str(tmp_path / "x.fbx")]) == 2
    one_line_error(capsys, "unknown motion format")


# ---------------------------------------------------------------------------- argument checks
@pytest.mark.parametrize(
    "args,what",
    [
        (["--fps", "-30"], "--fps"),
        (["--fps", "0"], "--fps"),
        (["--fps", "nan"], "--fps"),
        (["--guidance", "nan", "1"], "--guidance"),
        (["--guidance", "-5", "-5"], "--guidance"),
        (["--guidance", "1", "inf"], "--guidance"),
        (["--seed", "99999999999999999999999"], "--seed"),
        (["--seed", "-1"], "--seed"),
        (["--samples", "0"], "--samples"),
        (["--steps", "0"], "--steps"),
        (["--seconds", "-1"], "--seconds"),
        (["--seconds", "inf"], "--seconds"),
        (["--heading", "nan"], "--heading"),
        (["--constraints-fps", "0"], "--constraints-fps"),
        (["--constraints-fps", "-30"], "--constraints-fps"),
    ],
)
def test_generate_rejects_bad_numbers(tmp_path, capsys, no_model, args, what):
    """Malformed or below-range numbers are argparse's errors; above-range ones the request's one-line
    error naming the field (kinema.pipeline.request): exit 2 either way, before the model loads."""
    try:
        code = main(["generate", "walk", "--out", str(tmp_path / "o.bvh"), *args])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    field = what.removeprefix("--").replace("-", "_")
    assert (f"argument {what}:" in err or f"kinema: error: {field}:" in err) and "Traceback" not in err, err
    assert not (tmp_path / "o.bvh").exists()


@pytest.mark.parametrize(
    "cmd",
    [
        ["convert", "IN", "OUT.npz", "--fps", "0"],
        ["convert", "IN", "OUT.npz", "--fps", "-30"],
        ["convert", "IN", "OUT.npz", "--in-scale", "0"],
        ["export", "M", "--out", "O", "--guidance", "nan", "1"],
        ["evaluate", "--model", "M", "--seed", "-1"],
    ],
)
def test_other_commands_reject_bad_numbers(capsys, cmd):
    with pytest.raises(SystemExit) as exc:
        main(cmd)
    assert exc.value.code == 2
    assert "argument --" in capsys.readouterr().err


def test_largest_seed_is_accepted_by_torch():
    from kinema.cli._args import MAX_SEED, seed

    assert seed(str(MAX_SEED)) == MAX_SEED
    torch.Generator().manual_seed(MAX_SEED)


def test_steps_above_the_trained_length_is_an_error(tmp_path, capsys):
    out = tmp_path / "o.bvh"
    assert main(["generate", "walk", "--steps", "5000", "--seconds", "1", "--no-progress", "--out", str(out)]) == 2
    one_line_error(capsys, "5000", "1000")
    assert not out.exists()


# ---------------------------------------------------------------------------- timelines
def test_timeline_unknown_key_is_an_error_with_a_suggestion(tmp_path, capsys, no_model):
    from kinema.pipeline.timeline import parse_timeline

    with pytest.raises(KinemaError, match=r"segment 1: unknown key 'promt' \(did you mean 'prompt'\?\)"):
        parse_timeline([{"prompt": "a", "seconds": 1}, {"prompt": "b", "seconds": 4, "promt": "c"}])
    with pytest.raises(KinemaError, match=r"segment 0: unknown key 'speed';"):
        parse_timeline([{"prompt": "a", "seconds": 1, "speed": 2}])
    ok = parse_timeline([{"prompt": "a", "seconds": 1, "comment": "x", "_note": 1}])
    assert [(s.prompt, s.seconds) for s in ok] == [("a", 1.0)]
    path = tmp_path / "t.json"
    path.write_text(json.dumps([{"prompt": "walk", "seconds": 4, "secnds": 2}]))
    assert main(["generate", "--timeline", str(path), "--out", str(tmp_path / "o.bvh")]) == 2
    one_line_error(capsys, "t.json: segment 0: unknown key 'secnds' (did you mean 'seconds'?)")
    txt = tmp_path / "t.txt"
    txt.write_text("[]")
    assert main(["generate", "--timeline", str(txt), "--out", str(tmp_path / "o.bvh")]) == 2
    one_line_error(capsys, "must be a .json file")
