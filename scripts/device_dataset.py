"""Carry a dataset build to a rented GPU machine, whose upload limit (64 MiB with the repository) is far
below a build's features (0.5 GB for the human data), and rebuild it there.

    python scripts/device_dataset.py pack cache/bandai20h .gpu/bandai20h.pack    # here
    python scripts/device_dataset.py unpack .gpu/bandai20h.pack cache/bandai20h  # on the GPU machine

``pack`` keeps what the features are computed from, per frame of each clip of the chosen splits (default:
train, the only split ``kinema train`` reads): the pelvis position (float32), every joint's global rotation
(unit quaternion as int16, time-differenced) and the foot contacts (bits), all LZMA-compressed with the
build's JSON files. ``unpack`` rebuilds each clip's motion on the build's skeleton
(``Motion.from_global``) and its features with ``motion_to_features``, the build's own function, so the
rebuilt features match the build's up to the quantisation and the skeleton (pelvis-relative joint
positions differ by the spread of the source clips' bone lengths, ``meta.json: skeleton_offset_spread_m``).
``pack --check`` rebuilds here and prints the largest difference per feature group, in the build's
normalised units. Only clips of the packed splits are in the rebuilt ``clips.json``; its ``meta.json``
says so (``packed_splits``).
"""

from __future__ import annotations

import argparse
import io
import json
import lzma
import sys
import time
from pathlib import Path

import numpy as np
import torch
from safetensors.numpy import load_file

from kinema.data.build_folder import write_build_folder
from kinema.motion.core import Motion
from kinema.representation.kimodo_features import features_to_motion, motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton

QUAT_SCALE = 8192.0  # quaternion components in steps of 1.2e-4 (a rotation error under 0.02 degrees)
PELVIS_STEP_M = 1e-4


def _continuous(quat: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Quaternions ``(N, J, 4)`` with signs flipped so that each clip's frames follow on smoothly
    (q and -q are the same rotation; small steps compress well)."""
    out = quat.copy()
    ends = list(starts[1:]) + [len(quat)]
    for s, e in zip(starts, ends, strict=True):
        flip = np.sum(out[s + 1:e] * out[s:e - 1], axis=-1) < 0  # (T-1, J): sign change at this step
        sign = np.where(np.cumsum(flip, axis=0) % 2 == 1, -1.0, 1.0)
        out[s + 1:e] *= sign[..., None]
    return out


def _time_differences(x: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Frame-to-frame differences within each clip (its first frame kept), wrapping in ``x``'s integer type
    so that a wrapping cumulative sum restores ``x`` exactly."""
    d = x.copy()
    d[1:] = x[1:] - x[:-1]
    d[starts] = x[starts]
    return d


def _cumulative(d: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_time_differences` for one clip."""
    return np.cumsum(d, axis=0, dtype=d.dtype)


def pack(data: Path, out: Path, splits: list[str]) -> None:
    """Write the compact form of ``data``'s clips in ``splits`` to ``out``."""
    meta = json.loads((data / "meta.json").read_text())
    records = [c for c in json.loads((data / "clips.json").read_text()) if c["split"] in splits]
    clips = [c for c in records if not c["mirrored"]]  # a mirrored copy is rebuilt from its original
    feats = load_file(str(data / "features.safetensors"))["features"]
    rows = np.concatenate([np.arange(c["start"], c["start"] + c["length"]) for c in clips])
    # the build's own decoder (frame by frame): pelvis translation, global rotations, contacts
    motion = features_to_motion(torch.from_numpy(feats[rows]), Skeleton.from_dict(json.loads(
        (data / "skeleton.json").read_text())), float(meta["fps"]))
    pelvis, quat = motion.root_translation, motion.global_transforms()[0]
    starts = np.cumsum([0] + [c["length"] for c in clips])[:-1]
    q = _continuous(quat.numpy(), starts)
    q = np.round(q * QUAT_SCALE).astype(np.int16)
    p = np.round(pelvis.numpy() / PELVIS_STEP_M).astype(np.int32)
    dq, dp = _time_differences(q, starts), _time_differences(p, starts)
    contacts = np.packbits(motion.foot_contacts.numpy() > 0.5, axis=-1)
    buf = io.BytesIO()
    np.savez(buf, dpelvis=dp, dquat=dq, contacts=contacts,
             lengths=np.array([c["length"] for c in clips], dtype=np.int64))
    kept, start = [], 0
    for c in records:
        kept.append({**c, "start": start})
        start += c["length"]
    files = {name: (data / name).read_text() for name in ("meta.json", "skeleton.json", "stats.json")}
    files["clips.json"] = json.dumps(kept, ensure_ascii=False)
    files["packed_splits"] = json.dumps(splits)
    payload = {"arrays": buf.getvalue(), **{k: v.encode() for k, v in files.items()}}
    out.parent.mkdir(parents=True, exist_ok=True)
    with lzma.open(out, "wb", preset=6) as f:
        np.savez(f, **{k: np.frombuffer(v, dtype=np.uint8) for k, v in payload.items()})
    print(f"[pack] {len(clips)} clips (and {len(records) - len(clips)} mirrored copies), {len(rows)} frames "
          f"of {splits} -> {out} ({out.stat().st_size / 1e6:.1f} MB)")


def _read_pack(path: Path) -> tuple[dict, dict]:
    with lzma.open(path, "rb") as f:
        z = np.load(io.BytesIO(f.read()))
        payload = {k: z[k].tobytes() for k in z.files}
    arrays = dict(np.load(io.BytesIO(payload.pop("arrays"))))
    return arrays, {k: v.decode() for k, v in payload.items()}


def rebuild_features(arrays: dict, records: list[dict], skeleton: Skeleton, fps: float,
                     root_sigma: float) -> torch.Tensor:
    """Features of every clip record, in order, computed by the build's ``motion_to_features`` (a mirrored
    copy from its packed original's ``Motion.mirror``, as the build makes it)."""
    dq, dp = arrays["dquat"], arrays["dpelvis"]
    starts = np.cumsum(np.concatenate([[0], arrays["lengths"]]))
    contacts = np.unpackbits(arrays["contacts"], axis=-1)[:, :4].astype(np.float32)
    originals = [r["clip_id"] for r in records if not r["mirrored"]]
    motions = {}
    for clip_id, s, e in zip(originals, starts[:-1], starts[1:], strict=True):
        quat = torch.from_numpy(_cumulative(dq[s:e]).astype(np.float32) / QUAT_SCALE)
        pelvis = torch.from_numpy(_cumulative(dp[s:e]).astype(np.float64) * PELVIS_STEP_M).float()
        motions[clip_id] = Motion.from_global(skeleton, fps, pelvis, quat / quat.norm(dim=-1, keepdim=True),
                                              torch.from_numpy(contacts[s:e]))
    out = []
    for r in records:
        motion = motions[r["source_clip_id"]]
        out.append(motion_to_features(motion.mirror() if r["mirrored"] else motion, root_sigma=root_sigma))
    return torch.cat(out).to(torch.float32)


def _rebuild(path: Path) -> tuple[torch.Tensor, list[dict], dict, dict]:
    """A pack's rebuilt features, its clip records, its meta.json and its other files (parsed JSON)."""
    arrays, texts = _read_pack(path)
    files = {k: json.loads(v) for k, v in texts.items()}
    meta = files["meta.json"]
    features = rebuild_features(arrays, files["clips.json"], Skeleton.from_dict(files["skeleton.json"]),
                                float(meta["fps"]), float(meta["root_sigma_s"]))
    return features, files["clips.json"], meta, files


def unpack(path: Path, out_dir: Path) -> None:
    """Rebuild a build folder from a pack."""
    t0 = time.time()
    features, clips, meta, files = _rebuild(path)
    meta["packed_splits"] = files["packed_splits"]
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    folder_files = {name: files[name] for name in ("skeleton.json", "stats.json")}
    write_build_folder(out_dir, features, {"clips.json": clips, **folder_files}, meta, fps=float(meta["fps"]),
                       dim=features.shape[-1], t0=t0)
    print(f"[unpack] {out_dir}: {features.shape[0]} frames in {time.time() - t0:.0f} s")


def check(data: Path, path: Path) -> None:
    """Largest rebuilt-vs-built difference per feature group, in the build's normalised units."""
    rebuilt, clips, meta, files = _rebuild(path)
    original = {c["clip_id"]: c for c in json.loads((data / "clips.json").read_text())}
    feats = load_file(str(data / "features.safetensors"))["features"]
    rows = np.concatenate([np.arange(original[c["clip_id"]]["start"], original[c["clip_id"]]["start"] + c["length"])
                           for c in clips])
    std = torch.tensor(files["stats.json"]["std"], dtype=torch.float32)
    diff = (rebuilt - torch.from_numpy(feats[rows])).abs() / std
    layout = FeatureLayout(int(meta["layout"]["num_joints"]))
    for name, part in layout.split(diff).items():
        print(f"[check] {name}: max {float(part.max()):.4f} std, mean {float(part.mean()):.6f} std")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("pack")
    a.add_argument("data", type=Path)
    a.add_argument("out", type=Path)
    a.add_argument("--splits", nargs="+", default=["train"])
    a.add_argument("--check", action="store_true", help="rebuild here and print the differences")
    b = sub.add_parser("unpack")
    b.add_argument("pack", type=Path)
    b.add_argument("out", type=Path)
    args = p.parse_args(argv)
    if args.cmd == "pack":
        pack(args.data, args.out, args.splits)
        if args.check:
            check(args.data, args.out)
    else:
        unpack(args.pack, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
