"""Does a human model make the Quaternius humanoid actions (issue 38)? Held-out phrasings, measured.

    python scripts/humanoid_action_probes.py --model default --seeds 0 1 2 [--json out.json] [--after-walk]

For every phrasing of kinema.data.humanoid_actions.HELD_OUT_PROMPTS (no training caption uses them) and
"A person dances.", generate 5 s (``--seconds``: 5 is what ``kinema generate`` makes when not told; defaults:
50 DDIM steps, post-processing, grounding) at each seed and measure on the output (metres, Y up).
``--after-walk`` asks for each prompt as the second segment of a timeline, after 3 s of "A person walks
forward." (how users put actions into a scene), and measures that segment's frames alone.
The measures:

- kick (named side): the named foot's highest point above the pelvis at that frame (> 0 = above hip
  height) and the other foot's highest point above the floor; *passes* when the named foot goes above
  the pelvis while the other stays below half the pelvis' standing height;
- punch (named side): how far each hand reaches ahead of the pelvis along the body's forward (from the
  shoulders), its gain over the first frame; *passes* when the named hand gains 0.25 m or more and at
  least 0.1 m more than the other;
- jump: the highest the lower of the two toes gets above its standing height; *passes* above 0.10 m
  (both feet off the ground);
- roll: the lowest the head comes relative to the pelvis (negative = head below the pelvis: upside
  down); *passes* below 0 (a tuck that goes over);
- fall: the pelvis' lowest height as a share of its first frame's and its highest rise above the first
  frame (m); *passes* below 0.6 without a rise over 0.25 m (the training falls get down to 0.15-0.59 and
  rise 0.15 m at most; a fall that first leaps is not a fall);
- nod (yes / no): the range over the motion of the head's pitch (its forward axis above or below the
  horizontal) and of its yaw (that axis turned from the body's forward, from the shoulders), degrees;
  *passes* when the named one ranges over 15 degrees or more and more than the other (the training nods:
  pitch 24-25, yaw 0; head shakes: yaw 25-31, pitch 11-15);
- dance: pelvis travel and hand sway; reported, with the warning if any.

Every prompt also reports the generation's warnings (an unknown prompt is warned). The summary line per
action is the share of (prompt, seed) samples that pass.

``--as-learned`` measures the model as it would run if every action its captions name counted as
learned (an unlearned action's prompt is conditioned on its own words, not grounded, and
warned; a learned one is grounded on captions of the same action): the evidence for
``kinema export --action-probes`` (kinema.model.vocabulary), which then marks learned the actions that
pass there, so that users get what was measured.
"""

from __future__ import annotations

import argparse
import json

import torch

from kinema.data.humanoid_actions import HELD_OUT_PROMPTS
from kinema.evaluate.probe_measures import body_forward, head_ranges

DANCE = "A person dances."
WALK = "A person walks forward."
WALK_SECONDS = 3.0


def _ix(names) -> dict[str, int]:
    return {n: i for i, n in enumerate(names)}


def measure(content: str, P: torch.Tensor, names, Q: torch.Tensor | None = None) -> dict:
    """The measures of the module docstring for one generated motion: positions ``P (T, J, 3)``, global
    rotations ``Q (T, J, 4)`` (needed for nods only)."""
    ix = _ix(names)
    hips = P[:, ix["Hips"]]
    toes = P[:, [ix["Toes_L"], ix["Toes_R"]], 1]
    action = content.split("-")[0]
    out: dict = {}
    if action == "kick":
        side = content.split("-")[1][0].upper()
        other = "R" if side == "L" else "L"
        named, free = P[:, ix[f"Foot_{side}"]], P[:, ix[f"Foot_{other}"]]
        out["named_foot_over_pelvis_m"] = float((named[:, 1] - hips[:, 1]).max())
        out["other_foot_max_m"] = float(free[:, 1].max())
        out["pass"] = out["named_foot_over_pelvis_m"] > 0 and out["other_foot_max_m"] < 0.5 * float(hips[0, 1])
    elif action == "punch":
        fwd = body_forward(P, ix["Shoulder_L"], ix["Shoulder_R"])
        gain = {}
        for s in ("L", "R"):
            reach = ((P[:, ix[f"Hand_{s}"]] - hips) * fwd).sum(-1)
            gain[s] = float(reach.max() - reach[0])
        side = content.split("-")[1][0].upper()
        other = "R" if side == "L" else "L"
        out["named_hand_gain_m"], out["other_hand_gain_m"] = gain[side], gain[other]
        out["pass"] = gain[side] >= 0.25 and gain[side] - gain[other] >= 0.1
    elif action == "jump":
        lift = toes.min(dim=1).values - toes[0].min()
        out["both_feet_off_m"] = float(lift.max())
        out["pass"] = out["both_feet_off_m"] > 0.10
    elif action == "roll":
        out["head_over_pelvis_min_m"] = float((P[:, ix["Head"], 1] - hips[:, 1]).min())
        out["pass"] = out["head_over_pelvis_min_m"] < 0
    elif action == "fall":
        out["pelvis_low_share"] = float(hips[:, 1].min() / hips[0, 1])
        out["pelvis_rise_m"] = float(hips[:, 1].max() - hips[0, 1])
        out["pass"] = out["pelvis_low_share"] < 0.6 and out["pelvis_rise_m"] <= 0.25
    elif action == "nod":
        pitch, yaw = head_ranges(P, Q, ix["Head"], ix["Shoulder_L"], ix["Shoulder_R"])
        out["head_pitch_range_deg"], out["head_yaw_range_deg"] = pitch, yaw
        named, other = (pitch, yaw) if content == "nod-yes" else (yaw, pitch)
        out["pass"] = named >= 15 and named > other
    else:
        out["travel_m"] = float((hips[-1, [0, 2]] - hips[0, [0, 2]]).norm())
        out["hand_sway_m"] = float((P[:, ix["Hand_R"]] - P[:, ix["Chest"]]).std(dim=0).norm())
    return out


def run(model_name: str, seeds: list[int], seconds: float = 5.0, as_learned: bool = False,
        after_walk: bool = False) -> list[dict]:
    import kinema

    model = kinema.load_model(model_name)
    known = model.known_prompts
    if as_learned and known is not None:
        model.known_prompts = known.with_probes({a: (1, 1) for a in known.named_actions})
    rows = []
    cases = [(c, p) for c, ps in HELD_OUT_PROMPTS.items() for p in ps] + [("dance", DANCE)]
    for content, prompt in cases:
        for seed in seeds:
            if after_walk:
                res = model.generate(timeline=[{"prompt": WALK, "seconds": WALK_SECONDS},
                                               {"prompt": prompt, "seconds": seconds}], seed=seed)
            else:
                res = model.generate(prompt, seconds=seconds, seed=seed)
            start = round(WALK_SECONDS * res[0].fps) if after_walk else 0  # the prompt's own frames
            P, Q = res[0].positions.double()[start:], res[0].global_rotations.double()[start:]
            row = {"content": content, "prompt": prompt, "seed": seed, "warnings": list(res.report.warnings)}
            g = res.report.prompts[-1].get("grounding", {})
            row["grounded_on"] = [c["caption"] for c in g.get("captions", [])] if isinstance(g, dict) else []
            row.update(measure(content, P, list(res[0].skeleton.names), Q))
            rows.append(row)
            print(json.dumps(row))
    return rows


def summary(rows: list[dict]) -> dict[str, str]:
    out = {}
    for content in dict.fromkeys(r["content"] for r in rows):
        rs = [r for r in rows if r["content"] == content]
        warned = sum(bool(r["warnings"]) for r in rs)
        if "pass" in rs[0]:
            out[content] = f"{sum(r['pass'] for r in rs)}/{len(rs)} pass, {warned} warned"
        else:
            out[content] = f"{warned}/{len(rs)} warned"
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="default")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--seconds", type=float, default=5.0,
                    help="length of each generated motion (default 5, as kinema generate; the humanoid clips are "
                         "2.8-7 s, an action within 1 or 2 s of idle on either side)")
    ap.add_argument("--after-walk", action="store_true",
                    help=f"each prompt after {WALK_SECONDS:g} s of {WALK!r} in one timeline, measured on its own "
                         "frames")
    ap.add_argument("--json", help="write every row and the summary here")
    ap.add_argument("--as-learned", action="store_true",
                    help="measure as if every action the captions name were learned (evidence for kinema export "
                         "--action-probes)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    rows = run(args.model, args.seeds, seconds=args.seconds, as_learned=args.as_learned, after_walk=args.after_walk)
    s = summary(rows)
    for k, v in s.items():
        print(f"{k}: {v}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"model": args.model, "seeds": args.seeds, "seconds": args.seconds,
                       "as_learned": args.as_learned, "after_walk": args.after_walk, "rows": rows, "summary": s},
                      f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
