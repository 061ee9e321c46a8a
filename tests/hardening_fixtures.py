"""Helpers shared by the hardening tests (tests/test_hardening.py, tests/test_hardening_cli.py,
tests/test_generate_polish.py): the one-line error check, a fake model and the fixtures around it.
Import the fixtures into a test module by assignment: ``bvh_file = hardening_fixtures.bvh_file``."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from tests.test_bvh_errors import GOOD

SHIPPED = Path(__file__).resolve().parents[1] / "kinema/assets/models/default"
DEEP = "[" * 100000 + "]" * 100000
FAST = ["--steps", "2", "--seconds", "1", "--no-progress"]


def one_line_error(capsys, *needles: str) -> str:
    """The captured stderr, asserted to be one "kinema: error:" line containing every needle."""
    err = capsys.readouterr().err
    assert err.startswith("kinema: error:") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err
    return err


class Stop(Exception):
    """Raised by the fake model: the CLI got as far as calling generate."""


class FakeModel:
    """Stands in for `load_model(...)`: records the request of the generate call (as the keywords of
    the old call: ``what`` is the prompt or the timeline), generates nothing."""

    max_steps = 1000
    needs_rig = False

    def __init__(self, calls: list):
        self.calls = calls

    def generate(self, request, **kwargs):
        fields = {f.name: getattr(request, f.name) for f in dataclasses.fields(request)}
        what = request.prompt if request.timeline is None else request.timeline
        self.calls.append(fields | {"what": what})
        raise Stop


@pytest.fixture
def fake_model(monkeypatch):
    """The generate calls the CLI makes, recorded by a `FakeModel` that stands in for load_model."""
    calls: list = []
    monkeypatch.setattr("kinema.generate.load_model", lambda *a, **k: FakeModel(calls))
    return calls


@pytest.fixture
def no_model(monkeypatch):
    """Loading the model is a failure: the error must come before any heavy work."""

    def boom(*a, **k):
        raise AssertionError("the model was loaded before the bad input was reported")

    monkeypatch.setattr("kinema.generate.load_model", boom)


@pytest.fixture
def bvh_file(tmp_path) -> Path:
    """A small valid BVH file (tests/test_bvh.py's GOOD) in the test's temporary folder."""
    path = tmp_path / "good.bvh"
    path.write_text(GOOD)
    return path
