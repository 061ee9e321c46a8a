"""`kinema generate` shows residuals as a short table (cm, degrees), nothing without constraints, warnings
on stderr as one line each, and takes --threads / KINEMA_THREADS (issue: hardening, sections 1, 5, 6)."""

from __future__ import annotations

import json

import pytest
import torch

from kinema.cli import main
from kinema.cli.report import residual_table


def _run(args, capsys):
    code = main(args)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


@pytest.fixture()
def base(tiny_checkpoint, tmp_path):
    return [
        "generate",
        "A person walks forward.",
        "--model",
        str(tiny_checkpoint),
        "--steps",
        "2",
        "--seconds",
        "2",
        "--no-progress",
        "--threads",
        "1",
    ]


def test_no_constraints_no_table(base, tmp_path, capsys):
    code, out, err = _run([*base, "--out", str(tmp_path / "a.bvh")], capsys)
    assert code == 0 and "residuals" not in out and "warning" not in err


def test_table_in_cm_and_unreachable_target_warned(base, tmp_path, capsys):
    cons = tmp_path / "c.json"
    cons.write_text(
        json.dumps(
            [
                {"type": "root2d", "times": [1.0], "smooth_root_2d": [[0.2, 0.5]]},
                {"type": "right-hand", "times": [1.5], "positions": [[30.0, 1.2, 0.5]]},
            ]
        )
    )
    code, out, err = _run([*base, "--constraints", str(cons), "--out", str(tmp_path / "b.bvh")], capsys)
    assert code == 0
    lines = out.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("constraint residuals after post-processing"))
    table = "\n".join(lines[start:])
    assert "root path / waypoints" in table and "joint position targets" in table and " cm" in table
    (warning,) = [ln for ln in err.splitlines() if "out of reach" in ln]
    assert warning.startswith("kinema: warning: constraint not met: right-hand target at frame 30 (1.50 s) is ")


def test_threads_option_and_environment(base, tmp_path, capsys, monkeypatch):
    before = torch.get_num_threads()
    try:
        args = [a for a in base if a not in ("--threads", "1")]
        monkeypatch.setenv("KINEMA_THREADS", "1")
        assert _run([*args, "--out", str(tmp_path / "t.bvh")], capsys)[0] == 0
        assert torch.get_num_threads() == 1
        monkeypatch.setenv("KINEMA_THREADS", "many")
        code, _, err = _run([*args, "--out", str(tmp_path / "u.bvh")], capsys)
        assert code == 2 and "KINEMA_THREADS must be a positive integer" in err
        assert not (tmp_path / "u.bvh").exists()
        with pytest.raises(SystemExit):
            main([*args, "--threads", "0", "--out", str(tmp_path / "v.bvh")])
    finally:
        torch.set_num_threads(before)


def test_residual_table_rows():
    rep = {
        "exact": {
            "before": {"rotation_deg": {"mean": 20.0, "max": 30.0, "count": 2}},
            "after": {"rotation_deg": {"mean": 0.5, "max": 1.0, "count": 2}},
        }
    }
    table = residual_table([{}, rep])
    assert "joint rotation targets" in table and "30.00 deg" in table and "1.00 deg" in table
    assert table.splitlines()[2].split()[0] == "1"  # the second sample's row
    assert residual_table([{}, {}]) == ""


def test_preview_runs_ten_steps(tiny_checkpoint, tmp_path, capsys):
    args = [
        "generate",
        "A person walks.",
        "--model",
        str(tiny_checkpoint),
        "--seconds",
        "1",
        "--no-progress",
        "--threads",
        "1",
        "--preview",
        "--out",
        str(tmp_path / "p.bvh"),
    ]
    code, out, _ = _run(args, capsys)
    assert code == 0 and "10 DDIM steps" in out
    code, _, err = _run([*args[:-2], "--steps", "3", "--out", str(tmp_path / "q.bvh")], capsys)
    assert code == 2 and "either --preview or --steps" in err and not (tmp_path / "q.bvh").exists()


def test_summary_line_names_the_guidance_that_ran() -> None:
    from kinema.cli.report import guidance_words

    assert guidance_words("regular", (2.0, 2.0)) == ", regular guidance 2"
    assert guidance_words("separated", (2.0, 1.5)) == ", separated guidance 2 / 1.5"
    assert guidance_words("", (0.0, 0.0)) == ""
