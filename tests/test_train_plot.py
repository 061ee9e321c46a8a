"""`kinema train plot`: loss curves from a run's log.jsonl."""

from __future__ import annotations

import json

import pytest

from kinema.errors import KinemaError
from kinema.train.plot import moving_average, plot_losses, read_log


def test_moving_average_is_a_trailing_mean():
    assert moving_average([1.0, 3.0, 5.0, 7.0], 2) == [1.0, 2.0, 4.0, 6.0]
    assert moving_average([2.0, 4.0], 10) == [2.0, 3.0]


def test_plot_writes_a_png_and_keeps_the_last_record_of_a_relogged_step(tmp_path):
    recs = [{"step": s, "loss": 1.0 / s, "root_pos": 0.1, "phase": 1 if s < 50 else 2} for s in range(1, 101)]
    recs.append({"step": 100, "loss": 0.5, "phase": 2})  # a resumed run logged step 100 again
    (tmp_path / "log.jsonl").write_text("\n".join(json.dumps(r) for r in recs) + "\n")
    assert read_log(tmp_path)[-1]["loss"] == 0.5 and len(read_log(tmp_path)) == 100
    out = plot_losses(tmp_path)
    assert out == tmp_path / "loss.png" and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_names_the_bad_line(tmp_path):
    with pytest.raises(KinemaError, match="no training log"):
        plot_losses(tmp_path)
    (tmp_path / "log.jsonl").write_text('{"step": 1, "loss": 1.0}\nnot json\n')
    with pytest.raises(KinemaError, match=r"log.jsonl:2: not a JSON line"):
        read_log(tmp_path)


def test_any_rig_log_gets_one_panel(tmp_path):
    """An any-rig run logs only its x0 loss: the picture is one panel (no empty "terms" panel)."""
    from PIL import Image

    recs = [{"step": s, "loss": 1.0 / s, "s_per_step": 0.4} for s in range(50, 1001, 50)]
    (tmp_path / "log.jsonl").write_text("\n".join(json.dumps(r) for r in recs) + "\n")
    (tmp_path / "two").mkdir()
    (tmp_path / "two" / "log.jsonl").write_text("\n".join(json.dumps(r | {"root_pos": 0.1}) for r in recs) + "\n")
    one, two = Image.open(plot_losses(tmp_path)), Image.open(plot_losses(tmp_path / "two"))
    assert one.height == two.height and one.width < 0.7 * two.width
