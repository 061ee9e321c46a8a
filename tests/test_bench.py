"""kinema.bench on tiny inputs: the load generator, interleaved thread timing, the generation suite
(sweeps, cold CLI and phases), the report, and the training-modes comparison. Speed targets are not
asserted here (benchmarks print them); these tests check that every measurement runs and is reported."""

from __future__ import annotations

import json

import pytest

from kinema.bench.threads import bench_threads, cpu_load, format_threads, time_interleaved


def test_cpu_load_starts_and_kills_its_processes():
    with cpu_load(2) as procs:
        assert len(procs) == 2 and all(p.poll() is None for p in procs)
    assert all(p.poll() is not None for p in procs)
    with cpu_load(0) as procs:
        assert procs == []


def test_threads_are_timed_interleaved_and_restored():
    import torch

    before = torch.get_num_threads()
    seen = []
    times = time_interleaved(lambda: seen.append(torch.get_num_threads()), [1, 2], repeats=2)
    assert seen == [1, 2, 1, 2] and all(len(v) == 2 for v in times.values())
    assert torch.get_num_threads() == before
    rows = bench_threads(lambda: sum(range(1000)), (1, 2), loads=(0, 1), repeats=2)
    assert [(r.load, r.threads) for r in rows] == [(0, 1), (0, 2), (1, 1), (1, 2)]
    assert rows[0].speedup_vs_1 == 1.0 and rows[2].speedup_vs_1 == 1.0
    assert "x vs 1 thread" in format_threads(rows, "noop")


@pytest.fixture(scope="module")
def tiny_model(tiny_checkpoint):
    from kinema.generate import load_model

    return load_model(tiny_checkpoint)


def test_sweeps_report_seconds_per_motion(tiny_model):
    from kinema.bench.generate import bench_sweeps, format_sweeps

    rows = bench_sweeps(tiny_model, samples=(1, 2), durations=(1.0, 12.0), steps=2)
    assert [(r.sweep, r.value) for r in rows] == [("samples", 1), ("samples", 2), ("seconds", 1.0), ("seconds", 12.0)]
    assert rows[1].per_motion_s == pytest.approx(rows[1].total_s / 2)
    assert rows[3].segments >= 2  # longer than the model's window: a timeline of segments
    assert "s per motion" in format_sweeps(rows)


def test_cold_cli_and_phases_in_fresh_processes(tiny_checkpoint):
    from kinema.bench.cold import PHASES, cli_times, format_cold, phase_breakdown

    cli = cli_times(str(tiny_checkpoint), seconds=1.0, threads=1, steps=2)
    assert cli["cold_s"] > 0 and cli["warm_s"] > 0
    phases = phase_breakdown(str(tiny_checkpoint), seconds=1.0, threads=1, steps=2)
    assert set(PHASES) <= set(phases) and all(phases[k] >= 0 for k in PHASES)
    assert sum(phases[k] for k in PHASES) == pytest.approx(phases["total"], rel=1e-6)
    text = format_cold(cli, phases)
    assert "cold" in text and "text_encoding" in text


def test_suite_and_report(tiny_checkpoint, tmp_path):
    from kinema.bench.report import run_all, write_bench_report
    from kinema.bench.suite import GenerateSuiteOptions

    opts = GenerateSuiteOptions.quick(
        sections=("steps", "sweeps", "threads"),
        steps=(2,),
        samples=(1,),
        durations=(1.0,),
        seconds=1.0,
        loads=(0,),
        thread_repeats=1,
    )
    result = run_all(str(tiny_checkpoint), configs=("tiny",), suite=opts, progress=False)
    assert len(result["generate"]) == 4 and len(result["sweeps"]) == 2 and len(result["threads"]) == 2
    path = write_bench_report(result, tmp_path / "bench")
    text = path.read_text()
    for title in ("Training step", "DDIM steps", "Samples per call", "Torch threads"):
        assert title in text
    assert json.loads((tmp_path / "bench" / "report.json").read_text())["threads"][0]["threads"] == 1


def test_cli_bench_generate_quick(tiny_checkpoint, capsys):
    from kinema.cli import main

    assert (
        main(
            [
                "bench",
                "generate",
                "--model",
                str(tiny_checkpoint),
                "--quick",
                "--sections",
                "steps",
                "--steps",
                "2",
                "--seconds",
                "1",
                "--threads",
                "1",
            ]
        )
        == 0
    )
    assert "DDIM steps" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["bench", "generate", "--sections", "nope"])


def test_train_modes_fp32_vs_bf16(tiny_data):
    from kinema.bench.train_modes import bench_train_modes, format_modes

    rows, losses = bench_train_modes(
        tiny_data, "tiny", modes=("bf16",), steps=4, batch=2, warmup=1, tail=2, progress=False
    )
    assert [r.mode for r in rows] == ["fp32", "bf16"] and len(losses["bf16"]) == 4
    assert rows[0].speedup == 1.0 and rows[0].loss_rel_diff == 0.0
    assert 0 <= rows[1].loss_rel_diff < 0.5
    assert "x fp32" in format_modes(rows, 2)


def test_speed_section_peak_share_and_table(tiny_model):
    """Issue 37's section: the denoiser's matmul FLOPs are counted (the fused eval path hides them from
    torch's counter, so they are counted in training mode) and the table has a column per precision."""
    import torch

    from kinema.bench.precision import ROWS, denoiser_gflops, format_speed, matmul_peak

    denoiser = tiny_model.loaded.denoiser
    gflop, rate = denoiser_gflops(denoiser, rows=2, frames=20, seconds=0.05)
    assert gflop > 0 and rate > 0 and not denoiser.training
    assert matmul_peak(torch.float32, size=128, seconds=0.05) > 0
    one = {key: 0.5 for key, _, _ in ROWS} | {"samples_1": 1.0, "samples_4": 0.4, "samples_gain": 2.5}
    text = format_speed({"rounds": 3, "samples": [1, 4], "fp32": one, "bf16": one})
    assert "| samples=1 / samples=4 per motion | 2.50 | 2.50 |" in text and "fp32 | bf16" in text
