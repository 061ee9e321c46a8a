"""Record the shipped human model's outputs for the fixed cases of tests/reference_cases.py.

Run once, from the code *before* a refactor that must not change behaviour:
``OMP_NUM_THREADS=1 python scripts/record_reference_outputs.py tests/data/reference_outputs.npz``.
tests/test_reference_outputs.py then checks every later commit against the file. A deliberate change
of behaviour re-records only the cases it changes: ``... reference_outputs.npz --only timeline`` keeps
every other case (and the keyframe inputs) of the existing file.

``... --creatures tests/data/reference_outputs_creatures.npz`` records the creatures model's cases
(`creature_cases`, on a Quaternius rig below ``$KINEMA_DATASETS`` or ../shared/datasets) instead.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from reference_cases import CREATURE_RIG, cases, creature_cases  # noqa: E402
from reference_compare import motion_arrays  # noqa: E402

import kinema  # noqa: E402
from kinema.geometry.rotations import quat_to_axis_angle  # noqa: E402


def main(out: str, only: str | None = None) -> None:
    torch.set_num_threads(1)
    model = kinema.load_model(precision="fp32")
    seed_motion = model.generate("A person walks forward.", seconds=2.0, steps=5, seed=11, postprocess=False)[0]
    kf_rot = quat_to_axis_angle(seed_motion.local_rotations[[0, 30]].double()).numpy()
    kf_root = seed_motion.root_translation[[0, 30]].double().numpy()
    arrays = {"input_kf_rot": kf_rot, "input_kf_root": kf_root}
    if only is not None:
        with np.load(out) as old:
            arrays = {k: old[k] for k in old.files if not k.startswith(only)}
        kf_rot, kf_root = arrays["input_kf_rot"], arrays["input_kf_root"]
    for name, prompt, kwargs in cases(kf_rot, kf_root):
        if only is not None and not name.startswith(only):
            continue
        result = model.generate(prompt, **kwargs)
        for i, m in enumerate(result):
            arrays[f"{name}_{i}_root"] = m.root_translation.float().numpy()
            arrays[f"{name}_{i}_rot"] = m.local_rotations.float().numpy()
            arrays[f"{name}_{i}_pos"] = m.positions.float().numpy()
            arrays[f"{name}_{i}_contacts"] = m.foot_contacts.float().numpy()
        print(name, len(result), result.report.seconds)
    np.savez_compressed(out, **arrays)


def datasets() -> Path:
    return Path(os.environ.get("KINEMA_DATASETS") or Path(__file__).resolve().parents[2] / "shared/datasets")


def record_creatures(out: str) -> None:
    torch.set_num_threads(1)
    model = kinema.load_model("creatures", precision="fp32")
    arrays = {}
    for name, prompt, kwargs in creature_cases(str(datasets() / CREATURE_RIG)):
        result = model.generate(prompt, **kwargs)
        for i, m in enumerate(result):
            arrays.update({f"{name}_{i}_{k}": v for k, v in motion_arrays(m).items()})
        print(name, len(result), result.report.seconds)
    np.savez_compressed(out, **arrays)


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[0] == "--creatures":
        record_creatures(args[1])
    else:
        main(args[0], args[2] if len(args) == 3 and args[1] == "--only" else None)
