"""Every config read from JSON rejects unknown keys (a typo in a saved config is an error, not ignored)."""

import json

import pytest

from kinema.errors import KinemaError
from kinema.evaluate.retrieval import RetrievalConfig
from kinema.train.trainer import TrainConfig


def test_train_config_round_trip_and_typo():
    cfg = TrainConfig(steps=12, lr=3e-4)
    assert TrainConfig.from_dict(json.loads(json.dumps(cfg.__dict__))) == cfg
    with pytest.raises(KinemaError, match=r"unknown training settings: \['stepz'\]"):
        TrainConfig.from_dict({"stepz": 12})


def test_retrieval_config_round_trip_and_typo():
    cfg = RetrievalConfig()
    assert RetrievalConfig.from_dict(dict(cfg.__dict__)) == cfg
    with pytest.raises(KinemaError, match=r"unknown retrieval model settings: \['widht'\]"):
        RetrievalConfig.from_dict({"widht": 64})
