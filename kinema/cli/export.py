"""`kinema export RUN --out DIR`: pack a run's EMA weights as a small inference-only model folder.

This is how the default model inside the package is made (see kinema/assets/models/default/MODEL_CARD.md):
float16 weights plus checkpoint.json, no optimizer state. ``--guidance`` and ``--steps`` replace the
sampling defaults saved with the model, ``--grounding*`` the prompt-grounding default (kinema.model.grounding).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import add_grounding_arguments, grounding_overrides, non_negative_float, positive_int
from kinema.runtime import text_cache_dir


def register(sub) -> None:
    """Add the `export` sub-command to the top-level parser."""
    p = sub.add_parser("export", help="pack a trained checkpoint as an inference model folder (float16 EMA weights)")
    p.add_argument("model", type=Path, help="run folder (its newest checkpoint), checkpoint folder or model folder "
                                            "('default' and 'creatures' are the shipped ones: re-packing)")
    p.add_argument("--out", type=Path, required=True, help="model folder to write, e.g. kinema/assets/models/default")
    p.add_argument("--dtype", default="float16", choices=("float16", "bfloat16", "float32"), help="weight precision")
    p.add_argument("--guidance", type=non_negative_float, nargs=2, metavar=("W_TEXT", "W_CONSTR"),
                   help="default guidance weights saved with the model (finite, >= 0)")
    p.add_argument("--guidance-mode", choices=("separated", "regular"), default="separated",
                   help="the guidance mode a call without weights runs (kinema.diffusion.guidance): separated (text "
                        "and constraints weighted on their own: three denoiser branches on a constrained call) or "
                        "regular (one weight, W_TEXT, on text and constraints together: two branches; docs/speed.md)")
    p.add_argument("--steps", type=positive_int, help="default DDIM steps saved with the model")
    p.add_argument("--weights", default="ema", choices=("ema", "raw"),
                   help="EMA weights (default) or the raw optimiser weights (short fine-tunes, whose EMA still "
                        "mostly holds the starting weights)")
    add_grounding_arguments(p)
    p.add_argument("--root-stage", type=Path, metavar="RUN",
                   help="any-rig models: pack this root-stage run (`kinema train-anyrig-root`) with the model, so "
                        "generation samples the root first")
    p.add_argument("--known-prompts", type=Path, metavar="DATA",
                   help="dataset build whose train captions the model learned: their embeddings are saved as "
                        "known_prompts.safetensors, so that `generate` warns about prompts far from all of them")
    p.add_argument("--action-probes", type=Path, metavar="JSON",
                   help="with --known-prompts: per-action measurements of this model (scripts/humanoid_action_"
                        "probes.py --json); an action counts as learned when half its samples pass, instead of "
                        "by its number of training clips")
    p.add_argument("--fidelity", type=Path, nargs="+", metavar="JSON",
                   help="with --known-prompts: this model's caption-fidelity results (`kinema evaluate fidelity "
                        "--out`; a later file's actions replace an earlier one's): a prompt conditioned on a caption "
                        "whose action does not hold on its own captions is warned about")
    p.add_argument("--mix", nargs=2, metavar=("MODEL", "SHARE"),
                   help="weight-space ensemble: pack (1 - SHARE) x the run's weights + SHARE x MODEL's ('default' or "
                        "a folder: the model the run was fine-tuned from), e.g. --mix default 0.5 keeps part of "
                        "what the fine-tune learned and part of what it forgot (WiSE-FT)")
    p.add_argument("--action-expert", type=Path, metavar="RUN",
                   help="human models: pack this fine-tune's weights (a run or model folder trained with --init-from "
                        "the model) beside the model's own, to denoise the prompts that name one of "
                        "--expert-actions (kinema.model.action_expert)")
    p.add_argument("--expert-actions", nargs="+", metavar="ACTION",
                   help="with --action-expert: the actions it serves (names of kinema.model.actions, e.g. kick punch "
                        "jump roll crouch nod fall 'pick up')")
    p.add_argument("--expert-mirror-side", choices=("left", "right"), metavar="SIDE",
                   help="with --action-expert: the side (left or right) the expert does worse, measured with the "
                        "action probes; its prompts that name that side alone are generated as the mirror image of "
                        "the other side's (kinema.human.mirrored_request)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.diffusion.guidance import Guidance
    from kinema.errors import KinemaError
    from kinema.generate import resolve_model_path
    from kinema.model.export import export_model, load_weights

    if args.known_prompts is not None and not (args.known_prompts / "clips.json").is_file():
        raise KinemaError(f"{args.known_prompts}: not a dataset build (no clips.json); run `kinema data build`")
    probes = None
    if args.action_probes is not None:
        from kinema.model.vocabulary import read_action_probes

        if args.known_prompts is None:
            raise KinemaError("--action-probes: give --known-prompts DATA too (the probes qualify its actions)")
        probes = read_action_probes(args.action_probes)
    fidelity = None
    if args.fidelity is not None:
        from kinema.model.vocabulary import read_content_fidelity

        if args.known_prompts is None:
            raise KinemaError("--fidelity: give --known-prompts DATA too (the results qualify its captions)")
        fidelity = read_content_fidelity(args.fidelity)
    if (args.action_expert is None) != (args.expert_actions is None):
        raise KinemaError("--action-expert RUN and --expert-actions ACTION ... go together")
    expert = None if args.action_expert is None else (resolve_model_path(args.action_expert), args.expert_actions)
    if args.guidance is None and args.guidance_mode != "separated":
        raise KinemaError("--guidance-mode: give --guidance W_TEXT W_CONSTR too (the weights it is saved with)")
    guidance = None if args.guidance is None else Guidance(args.guidance_mode, *args.guidance)
    out = export_model(resolve_model_path(args.model), args.out, dtype=args.dtype, guidance=guidance,
                       sampling_steps=args.steps, ema=args.weights == "ema", grounding=grounding_overrides(args),
                       root_stage=args.root_stage, mix=_mix(args.mix), action_expert=expert,
                       expert_mirror_side=args.expert_mirror_side)
    loaded = load_weights(out)  # prove the folder loads
    if args.known_prompts is not None:
        _write_known_prompts(args.known_prompts, out, loaded.text_encoder_id, probes, fidelity)
    size = sum(p.stat().st_size for p in out.iterdir() if p.is_file())
    stage = "" if getattr(loaded, "root_stage", None) is None else ", with a root stage"
    mixed = loaded.info.get("export", {}).get("mixed_with")
    if mixed is not None:
        stage += f", {1 - mixed['share']:g} x its weights + {mixed['share']:g} x {mixed['source']}'s"
    if getattr(loaded, "expert", None) is not None:
        stage += f", with an action expert for {', '.join(loaded.expert.actions)}"
    print(f"wrote {out} ({size / 1e6:.2f} MB, step {loaded.info.get('step')}, {args.dtype}{stage}, "
          f"{loaded.guidance.mode.value} guidance {loaded.guidance.w_text:g}/{loaded.guidance.w_constr:g}, "
          f"{loaded.sampler.num_inference_steps} DDIM steps{_grounding_note(loaded)})")
    return 0


def _mix(mix: list[str] | None) -> tuple[Path, float] | None:
    """``--mix MODEL SHARE`` as (model folder, share); a share that is not a number is a one-line error."""
    if mix is None:
        return None
    from kinema.errors import KinemaError
    from kinema.generate import resolve_model_path

    try:
        share = float(mix[1])
    except ValueError:
        raise KinemaError(f"--mix: SHARE must be a number in [0, 1], got {mix[1]!r}") from None
    return resolve_model_path(mix[0]), share


def _write_known_prompts(data: Path, out: Path, encoder_id: str, probes: dict | None, fidelity: dict | None) -> None:
    """Embed the train captions of ``data`` with the model's text encoder into ``out``, with their clips'
    lengths, speeds and contents, the per-action ``probes`` (kinema.model.vocabulary.read_action_probes) and
    the per-content caption ``fidelity`` (read_content_fidelity) when given. Clips per action count each
    source clip once per side: the humanoid actions, built at two idle lengths, are one clip each."""
    from kinema.data.dataset import MotionDataset
    from kinema.data.phases import steady_speeds
    from kinema.data.phrasings import manner_phrases
    from kinema.model.vocabulary import KnownPrompts
    from kinema.text import get_text_encoder

    dataset = MotionDataset(data, "train")
    once = {(rec.get("source_clip_id", rec["clip_id"]), rec.get("mirrored")): rec for rec in dataset.clips}
    clips = [rec["captions"] for rec in once.values()]
    encoder = get_text_encoder(encoder_id, cache_dir=text_cache_dir())
    known = KnownPrompts.from_clips(clips, encoder, manner_phrases(), [rec["duration_s"] for rec in once.values()],
                                    steady_speeds(dataset, once.values()), [rec["content"] for rec in once.values()])
    if probes:
        known = known.with_probes(probes)
    if fidelity:
        known = known.with_content_fidelity(fidelity)
    learned = "" if not probes else "; measured: " + ", ".join(
        f"{a} {p}/{n}{'' if a in known.learned else ' (not learned)'}" for a, (p, n) in known.action_probes.items())
    print(f"wrote {known.save(out)} ({len(known.captions)} known captions{learned})")


def _grounding_note(loaded) -> str:
    """', grounding W (k K, T T)' for a model that saves a grounding default, else ''."""
    g = getattr(loaded, "grounding", None)
    if g is None or "grounding" not in loaded.info:
        return ""
    return f", grounding {g.weight:g} (top {g.top_k}, temperature {g.temperature:g})"
