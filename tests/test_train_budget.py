"""Training runtime options: the time budget (--minutes), run length fitted at the start, step timing,
bf16 autocast, and the one-command GPU script's CPU smoke run."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from kinema.errors import KinemaError
from kinema.train.trainer import TrainConfig, Trainer

REPO = Path(__file__).resolve().parents[1]


def _cfg(**kw) -> TrainConfig:
    base = dict(
        model="tiny",
        steps=1000,
        batch_size=2,
        lr=1e-3,
        warmup=5,
        text_encoder="hash-test-32",
        log_every=1000,
        ckpt_every=1000,
        max_seconds=3.0,
    )
    base.update(kw)
    return TrainConfig(**base)


def _log(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]


def test_time_budget_stops_cleanly_with_a_checkpoint_and_resumes(tiny_data, tmp_path):
    run = tmp_path / "run"
    trainer = Trainer(_cfg(), tiny_data, run)
    t0 = time.monotonic()
    last = trainer.run(progress=False, minutes=0.02)  # 1.2 s
    assert time.monotonic() - t0 < 30
    assert trainer.stopped_by_budget and 1 <= trainer.step < 1000
    assert last is not None and last.name == f"ckpt-{trainer.step:08d}"
    assert (run / "latest").read_text().strip() == last.name
    assert _log(run)[-1]["step"] == trainer.step  # the stopping step is logged
    again = Trainer(_cfg(steps=trainer.step + 2), tiny_data, run)
    assert again.resume() and again.step == trainer.step
    again.run(progress=False, minutes=10)
    assert not again.stopped_by_budget and again.step == trainer.step + 2


def test_no_budget_means_the_run_is_unchanged(tiny_data, tmp_path):
    a = Trainer(_cfg(steps=3), tiny_data, tmp_path / "a")
    a.run(progress=False)
    b = Trainer(_cfg(steps=3), tiny_data, tmp_path / "b", device="cpu")
    b.run(progress=False, minutes=60)
    assert not b.stopped_by_budget
    for (name, p), q in zip(a.model.state_dict().items(), b.model.state_dict().values(), strict=True):
        assert torch.equal(p, q), name


def test_cli_minutes(tiny_data, tmp_path, capsys):
    from kinema.cli import main

    out = tmp_path / "cli"
    args = [
        "train",
        "--config",
        "tiny",
        "--data",
        str(tiny_data),
        "--out",
        str(out),
        "--batch-size",
        "2",
        "--steps",
        "100000",
        "--text-encoder",
        "hash-test-32",
        "--no-progress",
        "--bf16",
        "--minutes",
        "0.01",
        "--threads",
        "1",
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "time budget of 0.01 min spent" in text and "--resume" in text
    assert (out / "latest").exists()
    with pytest.raises(SystemExit):  # argparse: the budget must be positive
        main([*args[:-4], "--minutes", "0"])


def test_time_steps_undoes_its_steps_and_set_total_steps_fits_the_schedule(tiny_data, tmp_path):
    trainer = Trainer(_cfg(steps=10**6, warmup=50), tiny_data, tmp_path / "t")
    before = {k: v.clone() for k, v in trainer.model.state_dict().items()}
    assert trainer.time_steps(2) > 0
    assert trainer.step == 0 and not trainer.optimizer.state
    for k, v in trainer.model.state_dict().items():
        assert torch.equal(v, before[k]), k
    trainer.set_total_steps(8)
    assert trainer.cfg.steps == 8 and trainer.phase1_steps == 4
    # a run whose length was fitted at step 0 is the run started with that length
    trainer.run(progress=False)
    ref = Trainer(_cfg(steps=8, warmup=50), tiny_data, tmp_path / "ref")
    ref.run(progress=False)
    for (name, p), q in zip(ref.model.state_dict().items(), trainer.model.state_dict().values(), strict=True):
        assert torch.equal(p, q), name
    with pytest.raises(KinemaError, match="run length"):
        trainer.set_total_steps(4)


def test_bf16_autocast_step_on_cpu(tiny_data, tmp_path):
    trainer = Trainer(_cfg(steps=2), tiny_data, tmp_path / "bf16", bf16=True)
    rec = trainer.train_step(trainer.model)
    assert torch.isfinite(torch.tensor(rec["loss"]))
    assert all(p.dtype == torch.float32 for p in trainer.model.parameters())  # weights stay float32


def test_gpu_script_cpu_smoke_run(bandai_root, tmp_path):
    """scripts/train_gpu.py end to end on the CPU: build a small dataset, tiny preset, a short budget,
    export; the exported folder loads and generates."""
    cmd = [
        sys.executable,
        str(REPO / "scripts/train_gpu.py"),
        "--minutes",
        "0.2",
        "--device",
        "cpu",
        "--root",
        str(bandai_root),
        "--data",
        str(tmp_path / "data"),
        "--limit",
        "4",
        "--runs",
        str(tmp_path / "runs"),
        "--models",
        str(tmp_path / "models"),
        "--name",
        "smoke",
        "--text-encoder",
        "hash-test-32",
        "--calibrate",
        "2",
        "--threads",
        "1",
        "--text-whiten",
        "0.05",
    ]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert time.monotonic() - t0 < 90, proc.stdout
    assert "[train] tiny" in proc.stdout and "[export]" in proc.stdout
    model_dir = tmp_path / "models" / "smoke"
    info = json.loads((model_dir / "checkpoint.json").read_text())
    assert info["model_config"]["width"] == 64 and info["step"] >= 1
    assert info["train_config"]["text_whiten"] == 0.05  # trained whitened, exported as a plain model
    import kinema

    motions = kinema.load_model(model_dir).generate("A person walks.", seconds=1.0, steps=2, postprocess=False)
    assert motions[0].num_frames == 20


def test_gpu_script_fine_tunes_from_a_pack_and_leaves_a_slim_run(tiny_data, tiny_checkpoint, tmp_path):
    """The fine-tune a GPU session runs: the dataset rebuilt from a pack (scripts/device_dataset.py), the
    starting model's preset and statistics, the fine-tune's options, and a slim float16 copy of the last
    checkpoint that `kinema export` turns into a model where it lands."""
    pack = tmp_path / "data.pack"
    subprocess.run([sys.executable, str(REPO / "scripts/device_dataset.py"), "pack", str(tiny_data), str(pack)],
                   check=True, capture_output=True, timeout=300)
    cmd = [sys.executable, str(REPO / "scripts/train_gpu.py"), "--minutes", "0.1", "--device", "cpu",
           "--init-from", str(tiny_checkpoint), "--pack", str(pack), "--data", str(tmp_path / "data"),
           "--runs", str(tmp_path / "runs"), "--models", str(tmp_path / "models"), "--name", "ft",
           "--text-encoder", "hash-test-32", "--calibrate", "2", "--threads", "1", "--lr", "3e-4",
           "--warmup", "2", "--phase1-fraction", "0", "--high-noise-share", "0.5", "--seed", "3",
           "--slim", str(tmp_path / "slim")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert "[train] fine-tuning from" in proc.stdout and "[train] tiny" in proc.stdout
    saved = json.loads((tmp_path / "runs/ft/train_config.json").read_text())
    assert (saved["lr"], saved["warmup"], saved["phase1_fraction"], saved["high_noise_share"], saved["seed"]) == \
           (3e-4, 2, 0.0, 0.5, 3)
    slim = tmp_path / "slim/ft"
    last = slim / (slim / "latest").read_text().strip()
    assert sorted(p.name for p in last.iterdir()) == ["checkpoint.json", "ema.safetensors", "model.safetensors"]
    from safetensors.torch import load_file

    assert all(v.dtype == torch.float16 for v in load_file(str(last / "model.safetensors")).values()
               if v.is_floating_point())
    out = tmp_path / "exported"
    exp = subprocess.run([sys.executable, "-m", "kinema", "export", str(slim), "--weights", "raw", "--out", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert exp.returncode == 0, exp.stderr[-2000:]
    start = json.loads((tiny_checkpoint / (tiny_checkpoint / "latest").read_text().strip() / "checkpoint.json")
                       .read_text())
    assert json.loads((out / "checkpoint.json").read_text())["stats"] == start["stats"]  # the starting model's
