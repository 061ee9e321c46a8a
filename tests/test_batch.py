"""`kinema batch`: resumable, crash-safe batch generation on local processes and on a local Ray head.

Generation is tiny (1-2 s motions, 2-5 DDIM steps, the shipped model). The crash test kills the whole
batch (driver and worker processes) with SIGKILL mid-way and reruns the same command: every job then
has exactly its files, each readable, one ``ok`` manifest record, and no temporary file is left. The
Ray test starts its own head on 127.0.0.1 (a private temp dir, killed by process group at the end).
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from tests.server_process import free_port

pytest.importorskip("pydantic")

#: Ray: every address on loopback, no usage report, and token auth with a token of this run's own (not
#: ~/.ray/auth_token, which other Ray users of the machine may have or lack)
ENV = os.environ | {
    "OMP_NUM_THREADS": "1",
    "RAY_USAGE_STATS_ENABLED": "0",
    "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0",
    "RAY_AUTH_MODE": "token",
    "RAY_AUTH_TOKEN": secrets.token_hex(32),
}


def _jobs(path: Path, n: int, seconds: float = 1.0, steps: int = 2, extra: list[str] = ()) -> Path:
    lines = [
        json.dumps(
            {
                "id": f"job{i:02d}",
                "prompt": "A person walks forward.",
                "seconds": seconds,
                "steps": steps,
                "seed": i,
                "format": "npz" if i % 3 == 2 else "bvh",
            }
        )
        for i in range(n)
    ]
    path.write_text("\n".join([*lines, *extra]) + "\n")
    return path


def _kinema(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "kinema", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
        env=ENV,
        **kw,
    )


def _ok_records(out: Path) -> list[dict]:
    path = out / "manifest.jsonl"
    if not path.exists():
        return []
    recs = []
    for line in path.read_text().splitlines():
        try:
            recs.append(json.loads(line))
        except json.JSONDecodeError:
            pass
    return [r for r in recs if r.get("status") == "ok"]


def _live(session: int) -> list[str]:
    """Processes still running (not zombies) in the session a test started."""
    ps = subprocess.run(["ps", "-o", "pid=,stat=", "-s", str(session)], capture_output=True, text=True).stdout
    return [line for line in ps.splitlines() if line.split() and "Z" not in line.split()[1]]


def _check_outputs(out: Path, ids: list[str], once: bool = True) -> None:
    """One readable file per output of each job's last ok record (and, with ``once``, exactly one ok record
    per job); nothing else in the folder."""
    from kinema import load_motion

    ok = _ok_records(out)
    if once:
        assert sorted(r["id"] for r in ok) == sorted(ids)
    ok = list({r["id"]: r for r in ok}.values())
    assert sorted(r["id"] for r in ok) == sorted(ids)
    files = {p.name for p in out.iterdir()} - {"manifest.jsonl", ".kinema-batch.lock"}
    assert files == {o for r in ok for o in r["outputs"]}
    for r in ok:
        for name in r["outputs"]:
            assert load_motion(out / name).num_frames == r["frames"]
        assert len(r["model_sha256"]) == 64 and r["residuals"] and r["input"]["id"] == r["id"]


def test_killed_batch_resumes_without_duplicates(tmp_path):
    ids = [f"job{i:02d}" for i in range(8)]
    jobs = _jobs(tmp_path / "jobs.jsonl", 8, seconds=2.0, steps=5, extra=["{not json"])
    out = tmp_path / "out"
    proc = _kinema("batch", str(jobs), "--out", str(out), "--workers", "2", "--no-progress")
    deadline = time.monotonic() + 120
    while len(_ok_records(out)) < 2:
        assert proc.poll() is None, proc.stdout.read()
        assert time.monotonic() < deadline, "no job finished in 120 s"
        time.sleep(0.02)
    proc.kill()  # SIGKILL to the driver, mid-batch: its workers must notice and exit by themselves
    proc.wait(30)
    deadline = time.monotonic() + 60
    while _live(proc.pid):
        assert time.monotonic() < deadline, f"orphaned workers: {_live(proc.pid)}"
        time.sleep(0.1)
    before = len(_ok_records(out))
    assert 2 <= before < 8, "the batch finished before it was killed: the test proves nothing"
    rerun = _kinema("batch", str(jobs), "--out", str(out), "--workers", "2", "--no-progress")
    text, _ = rerun.communicate(timeout=300)
    assert rerun.returncode == 1, text  # the bad line fails; every other job is done
    assert f"{8 - before} done, {before} already finished, 1 failed of 9 jobs" in text, text
    _check_outputs(out, ids)
    failed = [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines() if '"failed"' in x]
    assert failed and all(f["line"] == 9 and "not valid JSON" in f["error"] for f in failed)


def test_ctrl_c_stops_the_workers_and_exits_130(tmp_path):
    jobs = _jobs(tmp_path / "jobs.jsonl", 40, seconds=2.0, steps=5)
    out = tmp_path / "out"
    proc = _kinema(
        "batch",
        str(jobs),
        "--out",
        str(out),
        "--workers",
        "2",
        "--no-progress",
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # as in a terminal
    deadline = time.monotonic() + 120
    while not _ok_records(out):
        assert proc.poll() is None and time.monotonic() < deadline, proc.stdout.read()
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C sends: the whole foreground group
    text, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in text, text
    time.sleep(0.5)
    assert not _live(proc.pid)  # no worker left behind
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def test_resume_skips_finished_jobs_and_reruns_changed_ones(tmp_path):
    from kinema.batch.runner import run_batch

    jobs = _jobs(
        tmp_path / "jobs.jsonl",
        3,
        extra=[
            '{"prompt": "x", "colour": 1}',
            '{"id": "job00", "prompt": "y"}',
            '{"prompt": "z", "seconds": 1, "steps": 2, "constraints": '
            '[{"type": "root2d", "frame_indices": [99], "smooth_root_2d": '
            "[[0, 1]]}]}",
        ],
    )
    out = tmp_path / "out"
    first = run_batch(jobs, out, workers=1, progress=False)
    assert (first.done, first.skipped, first.failed, first.total) == (3, 0, 3, 6)
    assert any("colour" in e for e in first.errors) and any("also used on line 1" in e for e in first.errors)
    assert any("frame_indices" in e for e in first.errors)
    again = run_batch(jobs, out, workers=1, progress=False)
    assert (again.done, again.skipped) == (0, 3)
    lines = jobs.read_text().splitlines()
    lines[1] = lines[1].replace('"seed": 1', '"seed": 7')
    jobs.write_text("\n".join(lines[:3]) + "\n")
    (out / "job00.bvh").unlink()
    third = run_batch(jobs, out, workers=1, progress=False)
    assert (third.done, third.skipped, third.failed) == (2, 1, 0)
    _check_outputs(out, ["job00", "job01", "job02"], once=False)


def test_torn_manifest_line_and_stale_temp_files_are_cleaned(tmp_path):
    from kinema.batch.runner import run_batch

    jobs = _jobs(tmp_path / "jobs.jsonl", 2)
    out = tmp_path / "out"
    run_batch(jobs, out, workers=1, progress=False)
    with (out / "manifest.jsonl").open("a") as fh:
        fh.write('{"id": "job01", "status": "o')  # killed mid-line
    (out / ".job01.bvh.abc123_x.tmp").write_text("half a file")
    s = run_batch(jobs, out, workers=1, progress=False)
    assert (s.done, s.skipped) == (0, 2)
    assert (out / "manifest.jsonl").read_text().endswith("\n")
    _check_outputs(out, ["job00", "job01"])


def test_two_batches_cannot_share_a_folder(tmp_path):
    from kinema.batch.manifest import FolderLock
    from kinema.batch.runner import run_batch
    from kinema.errors import KinemaError

    (tmp_path / "out").mkdir()
    lock = FolderLock(tmp_path / "out")
    try:
        with pytest.raises(KinemaError, match="another kinema batch"):
            run_batch(_jobs(tmp_path / "jobs.jsonl", 1), tmp_path / "out", workers=1, progress=False)
    finally:
        lock.release()


def test_bench_table(tmp_path):
    from kinema.batch.bench import bench_batch, format_table

    rows = bench_batch([1], jobs=2, seconds=1.0, steps=2)
    assert rows[0]["motions"] == 2 and rows[0]["motions_per_min"] > 0 and rows[0]["speedup"] == 1.0
    table = format_table(rows, seconds=1.0, steps=2, executor="local")
    assert "| workers | motions |" in table and "| 1 | 2 | 0 |" in table



def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_batch_on_a_local_ray_head(tmp_path):
    pytest.importorskip("ray")
    ray_bin = Path(sys.executable).with_name("ray")
    if not ray_bin.exists():
        pytest.skip("the ray command is not installed next to this Python")
    port = free_port()
    temp = tempfile.mkdtemp(prefix="kr", dir="/tmp")  # short: Ray's socket paths must stay < 108 bytes
    head = subprocess.Popen(
        [
            str(ray_bin),
            "start",
            "--head",
            "--block",
            f"--port={port}",
            "--node-ip-address=127.0.0.1",
            "--num-cpus=2",
            "--include-dashboard=false",
            "--disable-usage-stats",
            f"--temp-dir={temp}",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
        start_new_session=True,
        env=ENV,
    )
    try:
        deadline = time.monotonic() + 120
        while not _listening(port):
            assert head.poll() is None and time.monotonic() < deadline, "the Ray head did not start"
            time.sleep(0.2)
        jobs = _jobs(tmp_path / "jobs.jsonl", 4)
        out = tmp_path / "out"
        proc = _kinema(
            "batch", str(jobs), "--out", str(out), "--ray", f"127.0.0.1:{port}", "--workers", "2", "--no-progress"
        )
        text, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, text
        assert "4 done" in text and "on 2 worker(s)" in text, text
        _check_outputs(out, [f"job{i:02d}" for i in range(4)])
        assert len({r["worker"] for r in _ok_records(out)}) >= 1
    finally:  # `ray start --block` does not exit on SIGTERM alone: its whole (own) process group goes
        os.killpg(head.pid, signal.SIGTERM)
        time.sleep(2)
        os.killpg(head.pid, signal.SIGKILL)
        head.wait(30)
        shutil.rmtree(temp, ignore_errors=True)
