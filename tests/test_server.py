"""The HTTP API (`kinema serve`), tested through a real uvicorn process on 127.0.0.1.

One server for the module (the shipped model, tiny limits: <= 2 s, <= 5 steps, <= 2 samples, one worker,
a queue of 8, 64 KiB bodies, an API key) serves every endpoint test, the security tests (server paths,
traversal, oversized bodies, CORS, keys), a 40-request load test and a bounded schemathesis run
against its own OpenAPI document. Every request goes to the loopback address only.
"""

from __future__ import annotations

import base64
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from server_process import free_port, stop_server

httpx = pytest.importorskip("httpx")
pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

KEY = "test-key-0123456789abcdef"
AUTH = {"Authorization": f"Bearer {KEY}"}
LIMITS = [
    "--workers",
    "1",
    "--queue",
    "8",
    "--max-seconds",
    "2",
    "--max-samples",
    "2",
    "--max-steps",
    "5",
    "--max-body-bytes",
    "65536",
    "--max-jobs",
    "16",
    "--job-ttl",
    "60",
    "--timeout",
    "60",
    "--threads",
    "1",
    "--read-timeout",
    "2",
]
TINY = {"prompt": "A person walks forward.", "seconds": 1, "steps": 2}
BLENDER = shutil.which("blender")
ADDON = Path(__file__).resolve().parents[1] / "integrations/blender"



def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """``(base URL, process)`` of a running `kinema serve`; stopped (its process group) at the end."""
    tmp = tmp_path_factory.mktemp("server")
    (tmp / "keys").write_text(f"# test key\n{KEY}\n")
    port = free_port()
    cmd = [
        sys.executable,
        "-m",
        "kinema",
        "serve",
        "--port",
        str(port),
        "--api-key-file",
        str(tmp / "keys"),
        "--log-level",
        "warning",
        *LIMITS,
    ]
    log = (tmp / "server.log").open("w")
    proc = subprocess.Popen(
        cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=os.environ | {"OMP_NUM_THREADS": "1"}
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            assert proc.poll() is None, (tmp / "server.log").read_text()
            try:
                if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, "server did not start in 120 s"
            time.sleep(0.2)
        yield url, proc
    finally:
        stop_server(proc)
        log.close()


def post(url: str, path: str, body, **kw):
    return httpx.post(url + path, json=body, headers=AUTH, timeout=60, **kw)


def _errors(resp) -> dict[str, str]:
    assert resp.status_code == 422, resp.text
    return {e["path"]: e["msg"] for e in resp.json()["detail"]}


# ----------------------------------------------------------------------------- endpoints
def test_health_models_and_api_key(server):
    url, _ = server
    health = httpx.get(f"{url}/healthz").json()
    assert health["status"] == "ok" and health["models"] == ["default"] and health["capacity"] == 9
    assert httpx.get(f"{url}/v1/models").status_code == 401
    assert httpx.get(f"{url}/v1/models", headers={"Authorization": "Bearer wrong-key-0123456789"}).status_code == 401
    models = httpx.get(f"{url}/v1/models", headers={"X-API-Key": KEY}).json()
    (m,) = models["models"]
    assert m["rig"]["name"] == "bandai-namco" and len(m["rig"]["joints"]) == 21 and m["rig"]["fps"] == 20
    assert m["limits"]["max_steps"] == 5 and models["limits"]["max_seconds"] == 2 and len(m["sha256"]) == 64
    assert set(models["formats"]) == {"bvh", "npz", "glb", "json", "csv"}
    spec = httpx.get(f"{url}/openapi.json").json()
    assert {"/v1/generate", "/v1/jobs", "/v1/jobs/{job_id}", "/v1/models", "/healthz"} <= set(spec["paths"])
    assert httpx.get(f"{url}/docs").status_code == 200


def test_generate_bvh_matches_the_request(server, tmp_path):
    from kinema import load_motion

    url, _ = server
    resp = post(url, "/v1/generate", TINY | {"seed": 3})
    assert resp.status_code == 200, resp.text
    body = resp.json()
    (motion,) = body["motions"]
    assert motion["encoding"] == "text" and motion["data"].startswith("HIERARCHY")
    (tmp_path / "m.bvh").write_text(motion["data"])
    loaded = load_motion(tmp_path / "m.bvh")
    assert loaded.num_frames == motion["frames"] == body["report"]["frames"] == 20
    assert body["report"]["steps"] == 2 and body["report"]["seed"] == 3 and body["rig"] == "bandai-namco"
    again = post(url, "/v1/generate", TINY | {"seed": 3}).json()
    assert again["motions"][0]["data"] == motion["data"]  # a seed fixes the result


def test_generate_npz_and_json_formats(server):
    url, _ = server
    npz = post(url, "/v1/generate", TINY | {"format": "npz", "samples": 2}).json()
    assert [m["filename"] for m in npz["motions"]] == ["motion_00.npz", "motion_01.npz"]
    arrays = np.load(io.BytesIO(base64.b64decode(npz["motions"][1]["data"])), allow_pickle=False)
    assert arrays["local_quats"].shape == (20, 21, 4)
    js = post(url, "/v1/generate", TINY | {"format": "json"}).json()["motions"][0]["data"]
    assert np.asarray(js["positions"]).shape == (20, 21, 3) and js["joint_names"][0] == "Hips"


def test_constraints_inline_bvh_and_residuals(server):
    url, _ = server
    bvh = post(url, "/v1/generate", TINY).json()["motions"][0]["data"]
    body = TINY | {
        "constraints": [
            {"type": "root2d", "frame_indices": [19], "smooth_root_2d": [[0.3, 0.8]]},
            {"type": "fullbody", "bvh": bvh, "source_frames": [0], "frame_indices": [0]},
        ]
    }
    resp = post(url, "/v1/generate", body)
    assert resp.status_code == 200, resp.text
    (res,) = resp.json()["report"]["residuals"]
    assert "exact" in res or "foot_lock" in res


def test_jobs_lifecycle_and_downloads(server):
    url, _ = server
    resp = post(url, "/v1/jobs", TINY | {"samples": 2})
    assert resp.status_code == 202, resp.text
    job = resp.json()
    assert resp.headers["location"] == f"/v1/jobs/{job['id']}"
    deadline = time.monotonic() + 60
    while job["status"] not in ("done", "failed"):
        assert time.monotonic() < deadline
        time.sleep(0.1)
        job = httpx.get(f"{url}/v1/jobs/{job['id']}", headers=AUTH).json()
    assert job["status"] == "done" and len(job["motions"]) == 2 and job["expires"] > job["finished"]
    result = httpx.get(url + job["result"], headers=AUTH).json()
    assert len(result["motions"]) == 2
    file = httpx.get(url + job["motions"][1], headers=AUTH)
    assert file.status_code == 200 and file.text == result["motions"][1]["data"]
    assert "motion_01.bvh" in file.headers["content-disposition"]
    assert httpx.get(f"{url}/v1/jobs/{job['id']}/motions/2", headers=AUTH).status_code == 404
    assert httpx.get(f"{url}/v1/jobs/{'0' * 32}", headers=AUTH).status_code == 404
    bad = post(
        url, "/v1/jobs", TINY | {"constraints": [{"type": "root2d", "frame_indices": [99], "smooth_root_2d": [[0, 1]]}]}
    )
    failed = bad.json()
    while failed["status"] not in ("done", "failed"):
        time.sleep(0.1)
        failed = httpx.get(f"{url}/v1/jobs/{failed['id']}", headers=AUTH).json()
    assert failed["status"] == "failed" and failed["error"][0]["path"] == "$.constraints[0].frame_indices"
    assert httpx.get(f"{url}/v1/jobs/{failed['id']}/result", headers=AUTH).status_code == 422


@pytest.mark.parametrize(
    ("change", "path", "words"),
    [
        ({"typo": 1}, "$.typo", "Extra inputs"),
        ({"seconds": 3}, "$.seconds", "less than or equal to 2"),
        ({"steps": 6}, "$.steps", "less than or equal to 5"),
        ({"format": "gltf"}, "$.format", "not implemented"),
        ({"objectives": [{"type": "reach"}]}, "$.objectives", "not supported"),
        ({"model": "../../etc"}, "$.model", "unknown model"),
        ({"rig": "smpl"}, "$.rig", "no model here drives this rig"),
        (
            {"constraints": [{"type": "root2d", "frame_indices": [5], "smooth_root_2d": [[1, 2, 3]]}]},
            "$.constraints[0].smooth_root_2d",
            "expected shape",
        ),
        (
            {"constraints": [{"type": "root2d", "frame_indices": [5], "smooth_root_2d": [[1, float("nan")]]}]},
            "$.constraints[0].smooth_root_2d[0][1]",
            "finite",
        ),
        ({"constraints": [{"type": "left-hand", "colour": 1}]}, "$.constraints[0].colour", "Extra inputs"),
    ],
)
def test_validation_errors_name_the_field(server, change, path, words):
    url, _ = server
    content = json.dumps(TINY | change).encode()  # NaN as the bare token Python's json writes
    resp = httpx.post(f"{url}/v1/generate", content=content, headers=AUTH | {"content-type": "application/json"})
    errors = _errors(resp)
    assert path in errors and words in errors[path], errors


# ----------------------------------------------------------------------------- security
def test_no_request_reads_a_server_path(server, tmp_path):
    url, _ = server
    secret_bvh = tmp_path / "server_side.bvh"
    secret_bvh.write_text(post(url, "/v1/generate", TINY).json()["motions"][0]["data"])
    for value in (str(secret_bvh), "../" * 8 + str(secret_bvh), "file://" + str(secret_bvh)):
        body = TINY | {"constraints": [{"type": "fullbody", "bvh": value, "source_frames": [0]}]}
        assert "never reads files" in _errors(post(url, "/v1/generate", body))["$.constraints[0].bvh"]
    timeline = tmp_path / "timeline.json"
    timeline.write_text(json.dumps([{"prompt": "walk", "seconds": 1}, {"prompt": "run", "seconds": 1}]))
    resp = post(url, "/v1/generate", {"prompt": str(timeline), "seconds": 1, "steps": 2})
    assert resp.status_code == 200 and resp.json()["report"]["segments"] == 1  # the text, not the file
    assert "$.constraints" in _errors(post(url, "/v1/generate", TINY | {"constraints": str(secret_bvh)}))
    assert "$.model" in _errors(post(url, "/v1/generate", TINY | {"model": "kinema/assets/models/default"}))
    for path in ("/v1/jobs/..%2F..%2Fetc%2Fpasswd", "/v1/jobs/../../etc/passwd", "/v1/jobs/%2e%2e/result"):
        assert httpx.get(url + path, headers=AUTH).status_code in (404, 422)


def test_oversized_bodies_are_refused(server):
    url, _ = server
    big = json.dumps(TINY | {"prompt": "x" * 70_000}).encode()
    resp = httpx.post(f"{url}/v1/generate", content=big, headers=AUTH | {"content-type": "application/json"})
    assert resp.status_code == 413 and "65536" in resp.json()["detail"]

    def chunks():  # no Content-Length: counted as it arrives
        for _ in range(20):
            yield b" " * 8192

    resp = httpx.post(f"{url}/v1/generate", content=chunks(), headers=AUTH | {"content-type": "application/json"})
    assert resp.status_code == 413
    assert httpx.get(f"{url}/healthz").status_code == 200


def test_a_body_that_never_arrives_times_out(server):
    """Issue 36: Content-Length promises more than is sent -> 408 after --read-timeout (2 s here), and
    the connection is closed (it was held open for over 40 s)."""
    url, _ = server
    host, port = url.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=30) as conn:
        conn.sendall(f"POST /v1/generate HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {KEY}\r\n"
                     "Content-Type: application/json\r\nContent-Length: 500\r\n\r\n{\"prompt\": ".encode())
        t0 = time.monotonic()
        answer = b""
        while chunk := conn.recv(65536):
            answer += chunk
        waited = time.monotonic() - t0
    assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
    assert b"nothing came for 2 s" in answer and 1.5 < waited < 15
    assert httpx.get(f"{url}/healthz").status_code == 200


def test_malformed_json_is_400_as_documented(server):
    """docs/server.md: a body that is no JSON text is a 400 (it was a 422 with a 'JSON decode error')."""
    url, _ = server
    headers = AUTH | {"content-type": "application/json"}
    for raw, where in ((b'{"prompt": "A person walks", ', "character 29"), (b"\xff\xfe", "character 0")):
        resp = httpx.post(f"{url}/v1/generate", content=raw, headers=headers)
        assert resp.status_code == 400, resp.text
        assert "not valid JSON" in resp.json()["detail"] and where in resp.json()["detail"]
    assert post(url, "/v1/generate", {"prompt": 3}).status_code == 422  # valid JSON, wrong field: still 422
    for body in (TINY | {"seconds": True}, {"timeline": [{"prompt": "A person walks.", "seconds": True}], "steps": 2},
                 TINY | {"postprocess": "no"}):  # issue 36: true was taken as 1 s
        resp = post(url, "/v1/generate", body)
        assert resp.status_code == 422 and ("boolean" in resp.text or "bool" in resp.text), resp.text


def test_a_broken_inline_bvh_names_no_server_path(server):
    url, _ = server
    body = TINY | {"constraints": [{"type": "fullbody", "bvh": "HIERARCHY\nROOT Hips\n{ nonsense",
                                    "source_frames": [0], "frame_indices": [0]}]}
    resp = post(url, "/v1/generate", body)
    assert resp.status_code in (400, 422), resp.text
    assert "/tmp" not in resp.text and "kinema-serve-" not in resp.text and tempfile.gettempdir() not in resp.text
    assert "bvh" in resp.text.lower()


def test_cors_is_off_and_public_binds_need_a_key(server, tmp_path, capsys):
    from kinema.cli import main

    url, _ = server
    pre = httpx.options(
        f"{url}/v1/generate", headers={"Origin": "https://example.org", "Access-Control-Request-Method": "POST"}
    )
    assert "access-control-allow-origin" not in pre.headers
    assert main(["serve", "--host", "0.0.0.0", "--port", str(free_port())]) == 2
    assert "--api-key-file" in capsys.readouterr().err
    (tmp_path / "weak").write_text("short\n")
    assert main(["serve", "--host", "0.0.0.0", "--api-key-file", str(tmp_path / "weak")]) == 2
    assert "at least 16" in capsys.readouterr().err


# ----------------------------------------------------------------------------- load, fuzzing, clients
def _burst(url: str, path: str, body: dict, n: int) -> list:
    barrier = threading.Barrier(n)
    out: list = [None] * n

    def one(i: int) -> None:
        barrier.wait()
        try:
            out[i] = httpx.post(url + path, json=body, headers=AUTH, timeout=120)
        except httpx.TransportError as err:
            out[i] = err

    threads = [threading.Thread(target=one, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(180)
    return out


def test_40_concurrent_requests_queue_of_8(server):
    url, proc = server
    body = {"prompt": "A person runs.", "seconds": 2, "steps": 5}
    post(url, "/v1/generate", body)  # warm: first-use allocations are not growth
    rss = []
    for _ in range(2):
        answers = _burst(url, "/v1/generate", body, 40)
        codes = [getattr(a, "status_code", repr(a)) for a in answers]
        assert set(codes) <= {200, 429}, codes
        assert codes.count(429) >= 1 and codes.count(200) >= 9
        assert all(int(a.headers["retry-after"]) >= 1 for a in answers if a.status_code == 429)
        rss.append(_rss_mb(proc.pid))
    jobs = _burst(url, "/v1/jobs", TINY, 40)
    assert {a.status_code for a in jobs} <= {202, 429}
    health = httpx.get(f"{url}/healthz").json()
    assert proc.poll() is None and health["jobs"] <= 16
    assert rss[1] - rss[0] < 64 and rss[1] < 3000, rss
    deadline = time.monotonic() + 120  # let the admitted jobs finish before the next test
    while httpx.get(f"{url}/healthz").json()["pending"]:
        assert time.monotonic() < deadline
        time.sleep(0.1)


def test_schemathesis_finds_no_server_error(server, tmp_path):
    pytest.importorskip("schemathesis")
    url, proc = server
    runner = "import sys; from schemathesis.cli import schemathesis; sys.argv[0] = 'st'; sys.exit(schemathesis())"
    cmd = [
        sys.executable,
        "-c",
        runner,
        "run",
        f"{url}/openapi.json",
        "-H",
        f"Authorization: Bearer {KEY}",
        "--checks",
        "not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance",
        "--phases",
        "examples,coverage,fuzzing",
        "-n",
        "30",
        "--seed",
        "20",
        "--generation-database",
        "none",
        "--no-shrink",
        "-w",
        "1",
        "--request-timeout",
        "60",
        "--no-color",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=240, cwd=tmp_path)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert proc.poll() is None


def test_blender_addon_client_without_blender(server):
    sys.path.insert(0, str(ADDON / "kinema_blender"))
    try:
        import client  # the add-on's pure-Python half (no bpy)
    finally:
        sys.path.remove(str(ADDON / "kinema_blender"))
    url, _ = server
    text, report = client.generate_bvh(url, prompt="A person waves.", seconds=1, steps=2, api_key=KEY)
    assert text.startswith("HIERARCHY") and report["frames"] == 20
    with pytest.raises(client.KinemaClientError, match=r"\$\.seconds"):
        client.generate_bvh(url, prompt="x", seconds=9, api_key=KEY)


@pytest.mark.skipif(BLENDER is None, reason="blender is not on PATH")
def test_blender_addon_imports_a_generated_motion(server, tmp_path):
    url, _ = server
    out = tmp_path / "blender.json"
    cmd = [
        BLENDER,
        "-b",
        "--factory-startup",
        "--python",
        str(ADDON / "headless_check.py"),
        "--",
        url,
        KEY,
        "A person walks forward.",
        "1",
        "2",
        str(out),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and out.exists(), done.stdout[-3000:] + done.stderr[-2000:]
    report = json.loads(out.read_text())
    assert report["result"] == ["FINISHED"] and report["prompt"] == "A person walks forward."
    assert "Hips" in report["bones"] and report["frame_range"][1] - report["frame_range"][0] >= 19
