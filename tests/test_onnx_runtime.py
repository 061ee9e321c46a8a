"""`kinema export-onnx` and the onnxruntime reference sampler (kinema.portable, docs/onnx_runtime.md).

The shipped model is exported once into a temporary folder; the same prompt and initial noise through
Python's ``generate(postprocess=False)`` and through the exported graphs with the numpy loop give joint
positions within :data:`MEAN_MM` / :data:`MAX_MM` (fp32): text alone, waypoints, a dense path, full-body
keyframes, and on the action expert; grounding from the JSON alone equals kinema.model.grounding; the
float16-weight graphs stay close; bad inputs are one-line errors. The export is shared with tests/test_web_runtime.py
(tests/onnx_export.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from kinema.errors import KinemaError

pytest.importorskip("onnxruntime", reason="pip install 'kinema[onnx]'")
pytest.importorskip("onnxscript", reason="pip install 'kinema[onnx]'")

from kinema.cli import main as cli_main  # noqa: E402
from kinema.geometry.rotations import quat_to_axis_angle  # noqa: E402
from kinema.motion.smoothing import smooth_time  # noqa: E402
from kinema.portable.noise import standard_normal, uniforms  # noqa: E402
from kinema.portable.runtime import OnnxHumanModel, read_manifest  # noqa: E402
from tests.onnx_export import export_once, fp32_pipeline  # noqa: E402

#: agreement of the fp32 onnxruntime path with Python's generate (joint positions, millimetres)
MEAN_MM, MAX_MM = 1.0, 5.0
PROMPT = "A person walks forward."
SECONDS = 5.0
WAYPOINTS = ((0.5, 3.0, 2.5), (1.0, 5.5, 4.95))  # (x, z, seconds)


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    return export_once(tmp_path_factory)


@pytest.fixture(scope="module")
def runtime(exported):
    return OnnxHumanModel(exported)


@pytest.fixture(scope="module")
def pipeline():
    return fp32_pipeline()


def torch_noise(seed: int, frames: int, dim: int) -> np.ndarray:
    """The initial noise ``generate`` draws for one sample of one segment with ``seed``."""
    return torch.randn((1, frames, dim), generator=torch.Generator().manual_seed(seed))[0].numpy()


def python_positions(pipeline, prompt, seed, waypoints=(), steps=None) -> np.ndarray:
    cons = []
    if waypoints:
        fps = pipeline.fps
        cons = [{"type": "root2d", "frame_indices": [round(t * fps) for _, _, t in waypoints],
                 "smooth_root_2d": [[x, z] for x, z, _ in waypoints]}]
    res = pipeline.generate(prompt, seconds=SECONDS, seed=seed, postprocess=False, constraints=cons, steps=steps)
    return res.motions[0].global_transforms()[1].numpy()


def distances_mm(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    d = np.linalg.norm(a - b, axis=-1) * 1000
    return float(d.mean()), float(d.max())


def test_export_writes_graphs_json_and_licence(exported):
    folder = exported
    m = read_manifest(folder)
    for name in ("denoiser.onnx", "denoiser.fp16.onnx", "action_expert.onnx", "text_encoder.onnx",
                 "text_encoder.fp16.onnx", "tokenizer.json", "vocab.txt", "kinema_runtime.json", "LICENSE.txt"):
        assert (folder / name).is_file(), name
    assert "CC BY-NC 4.0" in m["license"] and "CC BY-NC 4.0" in (folder / "LICENSE.txt").read_text()
    assert m["graphs"]["denoiser"]["opset"] == 18 and m["graphs"]["denoiser"]["fp32_max_abs_error"] < 1e-4
    assert m["fps"] == 20.0 and len(m["skeleton"]["names"]) == len(m["skeleton"]["offsets"]) == 21
    assert len(m["schedule"]["alphas_cumprod"]) == m["schedule"]["num_train_steps"]
    assert len(m["normalization"]["std"]) == m["feature_dim"] == m["layout"]["dim"]
    assert len(m["grounding"]["captions"]) == m["grounding"]["embeddings"]["shape"][0] > 100
    assert m["action_expert"]["actions"] and m["action_expert"]["graph"] == "action_expert"
    size = sum(f.stat().st_size for f in folder.iterdir()) / 1e6
    print(f"exported folder: {size:.1f} MB")


@pytest.mark.parametrize("prompt,seed,steps,graph", [(PROMPT, 3, 20, "denoiser"),
                                                     ("A man kicks with his left foot.", 4, 10, "action_expert")])
def test_onnx_runtime_agrees_with_generate(runtime, pipeline, prompt, seed, steps, graph):
    frames = round(SECONDS * pipeline.fps)
    out = runtime.generate(prompt, SECONDS, noise=torch_noise(seed, frames, runtime.m["feature_dim"]), steps=steps)
    assert out["graph"] == graph
    mean, worst = distances_mm(out["positions"], python_positions(pipeline, prompt, seed, steps=steps))
    print(f"{prompt!r} ({steps or 50} steps): onnxruntime vs generate {mean:.4f} mm mean, {worst:.4f} mm max")
    assert mean < MEAN_MM and worst < MAX_MM


def test_waypoints_agree_and_are_met_raw(runtime, pipeline):
    frames = round(SECONDS * pipeline.fps)
    noise = torch_noise(7, frames, runtime.m["feature_dim"])
    out = runtime.generate(PROMPT, SECONDS, waypoints=WAYPOINTS, noise=noise, steps=20)
    mean, worst = distances_mm(out["positions"], python_positions(pipeline, PROMPT, 7, WAYPOINTS, steps=20))
    print(f"waypoints (20 steps): onnxruntime vs generate {mean:.4f} mm mean, {worst:.4f} mm max")
    assert mean < MEAN_MM and worst < MAX_MM
    pelvis = smooth_time(torch.from_numpy(out["positions"][:, 0, [0, 2]]), 0.5 * pipeline.fps).numpy()
    for x, z, t in WAYPOINTS:  # the smoothed pelvis (what a root constraint sets) passes each waypoint
        assert np.hypot(*(pelvis[round(t * pipeline.fps)] - [x, z])) < 0.10


def test_dense_path_agrees_with_generate(runtime, pipeline):
    path = ((0.0, 0.5, 0.5), (0.6, 2.0, 2.0), (1.5, 3.5, 3.5))  # (x, z, seconds)
    frames = round(SECONDS * pipeline.fps)
    noise = torch_noise(8, frames, runtime.m["feature_dim"])
    out = runtime.generate(PROMPT, SECONDS, path=path, noise=noise, steps=10)
    cons = [{"type": "root2d", "dense": True, "frame_indices": [round(t * pipeline.fps) for *_, t in path],
             "smooth_root_2d": [[x, z] for x, z, _ in path]}]
    want = pipeline.generate(PROMPT, seconds=SECONDS, seed=8, postprocess=False, constraints=cons, steps=10)
    mean, worst = distances_mm(out["positions"], want.motions[0].global_transforms()[1].numpy())
    print(f"dense path (10 steps): onnxruntime vs generate {mean:.4f} mm mean, {worst:.4f} mm max")
    assert mean < MEAN_MM and worst < MAX_MM


def test_fullbody_keyframes_agree_with_generate(runtime, pipeline):
    src = pipeline.generate(PROMPT, seconds=SECONDS, seed=1, postprocess=False, steps=10).motions[0]
    aa, root = quat_to_axis_angle(src.local_rotations).numpy(), src.root_translation.numpy()
    frames = [40, 80]
    cons = [{"type": "fullbody", "frame_indices": frames, "local_joints_rot": aa[frames].tolist(),
             "root_positions": root[frames].tolist()}]
    want = pipeline.generate(PROMPT, seconds=SECONDS, seed=9, postprocess=False, steps=10, constraints=cons)
    noise = torch_noise(9, round(SECONDS * pipeline.fps), runtime.m["feature_dim"])
    out = runtime.generate(PROMPT, SECONDS, noise=noise, steps=10,
                           keyframes=[(f / pipeline.fps, root[f], aa[f]) for f in frames])
    mean, worst = distances_mm(out["positions"], want.motions[0].global_transforms()[1].numpy())
    print(f"full-body keyframes (10 steps): onnxruntime vs generate {mean:.4f} mm mean, {worst:.4f} mm max")
    assert mean < MEAN_MM and worst < MAX_MM
    posed = src.global_transforms()[1].numpy()
    for f in frames:  # the keyframed poses are met raw within a few centimetres
        assert np.linalg.norm(out["positions"][f] - posed[f], axis=-1).mean() < 0.03


def test_grounding_from_json_equals_python(runtime, pipeline):
    prompts = ["A person walks forward.", "Someone strolls slowly ahead.", "A person jabs with the right hand.",
               "A man kicks hard using his left leg.", "A person dances wildly.", "Somebody heads forward.",
               "A person walks backwards slowly."]
    for prompt in prompts:
        want = pipeline.ground_prompts([prompt])[prompt]
        emb, info = runtime.condition(prompt)
        assert info["status"] == want.status, prompt
        assert info["captions"][:1] == [c for c, _ in want.captions][:1], prompt
        assert np.abs(emb - want.embedding.numpy()[0]).max() < 1e-5, prompt


def test_fp16_weights_keep_the_motion(exported, runtime):
    noise = standard_normal(7, (100, runtime.m["feature_dim"]))
    half = OnnxHumanModel(exported, precision="fp16")
    mean, worst = distances_mm(half.generate(PROMPT, SECONDS, noise=noise, steps=20)["positions"],
                               runtime.generate(PROMPT, SECONDS, noise=noise, steps=20)["positions"])
    print(f"fp16 weights vs fp32 (20 steps): {mean:.3f} mm mean, {worst:.3f} mm max")
    assert mean < 2.0 and worst < 10.0


def test_seeded_noise_is_the_documented_generator():
    # mulberry32(1): the first outputs of the reference JavaScript implementation
    assert np.allclose(uniforms(1, 3), [0.6270739405881613, 0.002735721180215478, 0.5274470399599522])
    z = standard_normal(11, (200, 261))
    assert z.dtype == np.float32 and abs(float(z.mean())) < 0.02 and abs(float(z.std()) - 1) < 0.02
    assert np.array_equal(z, standard_normal(11, (200, 261))) and not np.array_equal(z, standard_normal(12, (200, 261)))


def test_bad_inputs_are_one_line_errors(runtime, tmp_path, capsys):
    with pytest.raises(KinemaError, match="seconds must be in"):
        runtime.generate(PROMPT, 30.0)
    with pytest.raises(KinemaError, match="outside the motion"):
        runtime.generate(PROMPT, 2.0, waypoints=[(0.0, 1.0, 3.0)])
    with pytest.raises(KinemaError, match="increasing frames"):
        runtime.generate(PROMPT, 2.0, path=[(0.0, 1.0, 1.0), (0.0, 2.0, 0.5)])
    with pytest.raises(KinemaError, match="rotations 21 x 3"):
        runtime.generate(PROMPT, 2.0, keyframes=[(1.0, (0.0, 0.9, 0.0), np.zeros((20, 3)))])
    with pytest.raises(KinemaError, match="non-empty"):
        runtime.generate("  ", 2.0)
    with pytest.raises(KinemaError, match="not an exported kinema folder"):
        OnnxHumanModel(tmp_path)
    assert cli_main(["export-onnx", "creatures", "--out", str(tmp_path / "x")]) == 2
    (tmp_path / "file").write_text("")
    assert cli_main(["export-onnx", "default", "--out", str(tmp_path / "file")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "only the human pipeline" in err[0] and "is a file" in err[1]
