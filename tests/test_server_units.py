"""Pieces of the HTTP server tested in-process: the bounded pool, the expiring job store, the request
timeout (504), configured CORS and the config rules. tests/test_server.py covers the real uvicorn process."""

from __future__ import annotations

import threading
import time

import pytest

pytest.importorskip("fastapi")
pytest.importorskip("httpx")

from kinema.errors import KinemaError  # noqa: E402
from kinema.server.config import ServerConfig, ServerLimits, is_loopback, read_api_keys  # noqa: E402
from kinema.server.jobs import JobStore, StoreFull  # noqa: E402
from kinema.server.pool import PoolFull, WorkerPool  # noqa: E402


def test_pool_admits_workers_plus_queue_then_refuses_and_frees_slots():
    pool = WorkerPool(workers=1, queue=2)
    gate = threading.Event()
    futures = [pool.submit(gate.wait, 10) for _ in range(3)]
    with pytest.raises(PoolFull) as full:
        pool.submit(gate.wait, 10)
    assert full.value.retry_after >= 1 and pool.pending == 3
    gate.set()
    for f in futures:
        f.result(10)
    deadline = time.monotonic() + 5
    while pool.pending and time.monotonic() < deadline:
        time.sleep(0.01)
    assert pool.pending == 0
    assert pool.submit(lambda: 42).result(5) == 42
    pool.shutdown()


def test_job_store_is_bounded_and_expires_finished_jobs():
    store = JobStore(max_jobs=2, ttl=0.2)
    a, b = store.create(), store.create()
    with pytest.raises(StoreFull):
        store.create()  # both still queued: nothing may be dropped
    store.update(a, status="done", finished=time.time())
    c = store.create()  # makes room by dropping the oldest finished job
    assert store.get(a.id) is None and store.get(b.id) is b and store.get(c.id) is c
    store.update(b, status="failed", finished=time.time() - 1)  # finished longer ago than the ttl
    assert store.get(b.id) is None and len(store) == 1


def test_config_rules(tmp_path):
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost") and is_loopback("127.3.4.5")
    assert not is_loopback("0.0.0.0") and not is_loopback("example.org") and not is_loopback("192.168.1.2")
    with pytest.raises(KinemaError, match="api-key-file"):
        ServerConfig(host="0.0.0.0")
    assert ServerConfig(host="0.0.0.0", api_keys=("k" * 16,)).host == "0.0.0.0"
    with pytest.raises(KinemaError, match="positive"):
        ServerLimits(max_samples=0)
    (tmp_path / "empty").write_text("# nothing\n\n")
    with pytest.raises(KinemaError, match="holds no key"):
        read_api_keys(tmp_path / "empty")


@pytest.fixture(scope="module")
def registry():
    from kinema.server.models import ModelRegistry

    return ModelRegistry.load(["default"])


def test_slow_generation_answers_504_and_cors_when_configured(registry):
    from fastapi.testclient import TestClient

    from kinema.server.app import create_app

    limits = ServerLimits(max_seconds=2, max_steps=5, timeout_s=0.001)
    config = ServerConfig(cors_origins=("https://tool.example",), limits=limits)
    with TestClient(create_app(config, registry)) as client:
        resp = client.post("/v1/generate", json={"prompt": "A person walks.", "seconds": 2, "steps": 5})
        assert resp.status_code == 504 and "/v1/jobs" in resp.json()["detail"]
        pre = client.options(
            "/v1/generate", headers={"Origin": "https://tool.example", "Access-Control-Request-Method": "POST"}
        )
        assert pre.headers["access-control-allow-origin"] == "https://tool.example"
        other = client.options(
            "/v1/generate", headers={"Origin": "https://evil.example", "Access-Control-Request-Method": "POST"}
        )
        assert "access-control-allow-origin" not in other.headers


def test_model_specs_and_lookup_by_name_and_rig(registry):
    from kinema.server.errors import RequestError
    from kinema.server.models import ModelRegistry, ServedModel, parse_model_spec

    assert parse_model_spec("default") == ("default", "default")
    assert parse_model_spec("walker=runs/walk") == ("walker", "runs/walk")
    assert parse_model_spec("runs/walk")[0] == "walk"
    base = registry.models["default"]
    two = ModelRegistry([base, ServedModel("second", base.model, base.sha256)])
    assert two.resolve(None, None) is base and two.resolve("second", "bandai-namco").name == "second"
    with pytest.raises(RequestError, match="does not drive rig"):
        two.resolve("second", "smpl")
    with pytest.raises(KinemaError, match="same name"):
        ModelRegistry([base, base])
