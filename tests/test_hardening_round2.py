"""Issue 36 (hardening, round 2): inputs that used to end in a traceback, a hang or a silently wrong
file are one-line errors (exit 2 in the CLI) or honest results. Shared helpers:
tests/hardening_fixtures.py."""

from __future__ import annotations

import numpy as np
import pytest

from kinema.cli import main
from kinema.errors import KinemaError
from kinema.io import load_motion
from tests import hardening_fixtures as fixtures
from tests.hardening_fixtures import one_line_error

bvh_file = fixtures.bvh_file


# ---------------------------------------------------------------------------- npz inputs
def _npz_with(tmp_path, bvh_file, key: str, value: np.ndarray, name: str):
    good = tmp_path / "good.npz"
    load_motion(bvh_file).save(good)
    d = dict(np.load(good))
    d[key] = value(d[key])
    bad = tmp_path / name
    np.savez(bad, **d)
    return bad


@pytest.mark.parametrize("key", ["joint_names", "local_quats"])
def test_npz_object_array_is_one_line_error(tmp_path, bvh_file, capsys, key):
    bad = _npz_with(tmp_path, bvh_file, key, lambda a: np.array(list(a), dtype=object), "obj.npz")
    with pytest.raises(KinemaError, match=f"obj.npz: '{key}' is an object array"):
        load_motion(bad)
    out = tmp_path / "o.bvh"
    assert main(["convert", str(bad), str(out)]) == 2
    one_line_error(capsys, "obj.npz", key, "object array")
    assert not out.exists()


def test_npz_zero_quaternions_are_refused(tmp_path, bvh_file, capsys):
    def zero_one(q):
        q = q.copy()
        q[1, 1] = 0.0
        return q

    bad = _npz_with(tmp_path, bvh_file, "local_quats", zero_one, "zero.npz")
    with pytest.raises(KinemaError, match="zero length .*frame 1, joint 1"):
        load_motion(bad)
    bad = _npz_with(tmp_path, bvh_file, "local_quats", np.zeros_like, "allzero.npz")
    out = tmp_path / "o.png"
    assert main(["render", str(bad), "--out", str(out)]) == 2
    one_line_error(capsys, "allzero.npz", "zero length")
    assert not out.exists()
