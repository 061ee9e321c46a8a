"""Numbers to check a filmstrip against: motion statistics of generated BVH files vs ground-truth clips.

    python scripts/gallery_stats.py gen out/gallery/walk.bvh out/gallery/bow.bvh ...
    python scripts/gallery_stats.py gt --data cache/bandai20 --content walk bow kick

Per motion (metres, seconds, degrees; Y up): mean horizontal pelvis speed, largest trunk lean (hips ->
head against +Y), highest hand above the head, hand sway (std of the right hand relative to the chest),
highest toe lift above its lowest point, mean joint jerk. ``gt`` averages over the non-mirrored clips of
each content label (all splits). Used for the default model card's gallery table.
"""

from __future__ import annotations

import argparse

import torch

from kinema.evaluate.metrics import position_jerk


def motion_stats(positions: torch.Tensor, fps: float, names: list[str]) -> dict[str, float]:
    """``positions (T, J, 3)`` in metres -> the statistics above."""
    ix = {n: i for i, n in enumerate(names)}
    hips, head, chest = positions[:, ix["Hips"]], positions[:, ix["Head"]], positions[:, ix["Chest"]]
    hands = positions[:, [ix["Hand_L"], ix["Hand_R"]]]
    toes = positions[:, [ix["Toes_L"], ix["Toes_R"]]]
    T = positions.shape[0]
    dist = (hips[1:, [0, 2]] - hips[:-1, [0, 2]]).norm(dim=-1).sum()
    trunk = head - hips
    lean = torch.rad2deg(torch.acos((trunk[:, 1] / trunk.norm(dim=-1)).clamp(-1, 1))).max()
    return {
        "speed m/s": float(dist / max(T - 1, 1) * fps),
        "lean deg": float(lean),
        "hand over head m": float((hands[..., 1].max(dim=1).values - head[:, 1]).max()),
        "hand sway m": float((positions[:, ix["Hand_R"]] - chest).std(dim=0).norm()),
        "toe lift m": float((toes[..., 1] - toes[..., 1].min()).max()),
        "jerk m/s^3": position_jerk(positions, fps),  # the evaluation's jerk metric
    }


def _print(rows: list[tuple[str, dict[str, float]]]) -> None:
    keys = list(rows[0][1])
    print("| motion | " + " | ".join(keys) + " |")
    print("|---|" + "---:|" * len(keys))
    for name, st in rows:
        print(f"| {name} | " + " | ".join(f"{st[k]:.2f}" if abs(st[k]) < 100 else f"{st[k]:.0f}" for k in keys) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["gen", "gt"])
    ap.add_argument("files", nargs="*", help="BVH files (gen)")
    ap.add_argument("--data", default="cache/bandai20")
    ap.add_argument("--content", nargs="*", default=[])
    args = ap.parse_args()
    rows = []
    if args.mode == "gen":
        from kinema.io.bvh import read_bvh

        for f in args.files:
            m = read_bvh(f)
            rows.append((f, motion_stats(m.global_transforms()[1], m.fps, list(m.skeleton.names))))
    else:
        from kinema.data.dataset import MotionDataset
        from kinema.representation.kimodo_features import features_to_motion

        per: dict[str, list[dict[str, float]]] = {c: [] for c in args.content}
        for split in ("train", "val", "test"):
            ds = MotionDataset(args.data, split)
            for i, rec in enumerate(ds.clips):
                if rec["content"] in per and not rec["mirrored"]:
                    m = features_to_motion(ds[i]["features"], ds.skeleton, ds.fps)
                    per[rec["content"]].append(motion_stats(m.global_transforms()[1], m.fps, list(ds.skeleton.names)))
        for c, sts in per.items():
            if sts:
                mean = {k: sum(s[k] for s in sts) / len(sts) for k in sts[0]}
                rows.append((f"GT {c} ({len(sts)} clips)", mean))
    if rows:
        _print(rows)
    else:
        print("nothing to report")


if __name__ == "__main__":
    main()
