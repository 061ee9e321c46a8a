"""kinema.runtime: thread count from the argument, KINEMA_THREADS or the measured default; device names."""

from __future__ import annotations

import pytest
import torch

from kinema.errors import KinemaError
from kinema.runtime import ENV_VAR, configure_threads, default_threads, resolve_device


@pytest.fixture(autouse=True)
def _restore_threads(monkeypatch):
    """Every test leaves torch's thread count and KINEMA_THREADS as it found them."""
    before = torch.get_num_threads()
    monkeypatch.delenv(ENV_VAR, raising=False)
    yield
    torch.set_num_threads(before)


def test_argument_wins_over_the_environment(monkeypatch):
    monkeypatch.setenv(ENV_VAR, "2")
    assert configure_threads(1) == 1
    assert torch.get_num_threads() == 1


def test_environment_variable_is_used_without_an_argument(monkeypatch):
    monkeypatch.setenv(ENV_VAR, " 1 ")
    assert configure_threads() == 1 and torch.get_num_threads() == 1
    monkeypatch.setenv(ENV_VAR, "2")
    assert configure_threads() == 2 and torch.get_num_threads() == 2


@pytest.mark.parametrize("bad", ["abc", "0", "-3", "1.5", "2x"])
def test_bad_environment_value_names_the_variable(monkeypatch, bad):
    monkeypatch.setenv(ENV_VAR, bad)
    with pytest.raises(KinemaError, match=ENV_VAR):
        configure_threads()


@pytest.mark.parametrize("bad", [0, -1, True, 1.0, "two"])
def test_bad_argument_is_refused(bad):
    with pytest.raises(KinemaError, match="--threads"):
        configure_threads(bad)


def test_empty_environment_value_means_the_default(monkeypatch):
    monkeypatch.setenv(ENV_VAR, "")
    assert configure_threads() == default_threads()


def test_default_uses_a_second_thread_only_on_idle_cores():
    assert default_threads(cores=2, load=0.2) == 2
    assert default_threads(cores=2, load=0.3) == 1  # under 1.75 idle cores: one thread
    assert default_threads(cores=2, load=1.5) == 1
    assert default_threads(cores=16, load=0.0) == 2  # generation: capped at 2
    assert default_threads(cores=16, load=0.0, cap=None) == 16  # training: every idle core
    assert default_threads(cores=16, load=10.0, cap=None) == 6
    assert default_threads(cores=16, load=15.0, cap=None) == 1
    assert default_threads(cores=1, load=0.0) == 1


def test_repeated_calls_survive_the_interop_pool_being_fixed():
    torch.ones(64, 64) @ torch.ones(64, 64)  # parallel work has run: interop can no longer change
    assert configure_threads(1) == 1
    assert configure_threads(2) == 2


def test_resolve_device():
    assert resolve_device(None).type == "cpu"
    assert resolve_device("CPU").type == "cpu"
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(KinemaError, match="--device"):
        resolve_device("tpu")
    with pytest.raises(KinemaError, match="--device"):
        resolve_device("meta")
    if not torch.cuda.is_available():
        with pytest.raises(KinemaError, match="no CUDA"):
            resolve_device("cuda")
