"""Action experts: a second set of weights, inside one model folder, for the actions its main weights lack.

Why (issue 38, docs/training.md "Stop 53"): the shipped human model was trained on the Bandai Namco
captures; a fine-tune on those plus the CC0 Quaternius humanoid clips learns kicks, jumps and rolls, but on
these CPUs every fine-tune measured so far (stops 50-52: plain, rehearsed, anchored, weight-averaged) also
lost part of the old contents (old-suite R@3 80 or less against the shipped 96.7, FID 0.26-0.60 against
0.17). So the model keeps both: its main weights, unchanged, for everything it knew, and the fine-tune's
weights for the prompts that name one of the actions the fine-tune added. The two networks share the
architecture, features, statistics, text encoder, sampler and guidance (checked when the folder is
written and again when it is loaded), so routing changes only which weights denoise.

Routing is per denoiser pass, by the words of that pass's prompt (kinema.model.actions.actions_in): a
prompt that names one of ``actions`` ("Someone delivers a kick with the left foot." names 'kick') runs on
the expert, every other prompt on the main weights. A timeline routes each segment (and each join
window, by its prompt) on its own, so "walks, then kicks" walks on the main weights and kicks on the
expert's. Generation reports which weights served each prompt.

``mirror_side`` (optional, "left" or "right"): the side the expert does worse, as measured by the action
probes; a request whose expert prompt names that side alone is generated as its mirror image
(kinema.human.mirrored_request).

``checkpoint.json`` holds the entry under ``"action_expert"``: its ``actions``, the ``weights`` file name
(``action_expert.safetensors``), its ``mirror_side`` if any and where the weights came from (``source``,
``step``, ``train_config``), written by ``kinema export MODEL --action-expert RUN --expert-actions ...
[--expert-mirror-side SIDE]``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import torch

from kinema.errors import KinemaError
from kinema.model.actions import ACTION_WORDS, actions_in
from kinema.model.denoiser import Denoiser
from kinema.model.sides import SIDES, sides

#: the expert's weights file in a model folder
WEIGHTS_FILE = "action_expert.safetensors"
#: what a model and its expert must share (checkpoint.json keys): one network in one feature space
MUST_MATCH = ("model_config", "feature_layout", "stats", "text_encoder", "fps", "skeleton")


def expert_actions(actions: Iterable[str], where: str = "action expert") -> tuple[str, ...]:
    """``actions`` checked against kinema.model.actions.ACTION_WORDS, sorted and without repeats; an empty
    list or an unknown name is a one-line `KinemaError` that lists the known ones."""
    out = tuple(sorted(set(actions)))
    if not out:
        raise KinemaError(f"{where}: name at least one action the expert serves")
    unknown = [a for a in out if a not in ACTION_WORDS]
    if unknown:
        raise KinemaError(f"{where}: unknown actions {unknown}; known: {', '.join(ACTION_WORDS)}")
    return out


def mirror_side(side, where: str = "action expert") -> str | None:
    """``side`` checked: None, "left" or "right"; anything else is a one-line `KinemaError`."""
    if side is not None and side not in SIDES:
        raise KinemaError(f"{where}: mirror_side must be one of {', '.join(SIDES)}, got {side!r}")
    return side


@dataclass(frozen=True)
class ActionExpert:
    """The expert weights of a model folder (a loaded, frozen `Denoiser`), the actions they serve and the
    side whose prompts it generates as mirror images (None: none)."""

    actions: tuple[str, ...]
    denoiser: Denoiser
    entry: Mapping
    mirror_side: str | None = None

    def serves(self, prompt: str) -> bool:
        """Whether a prompt names one of the expert's actions."""
        return bool(actions_in(prompt) & frozenset(self.actions))

    def mirrors(self, prompt: str) -> bool:
        """Whether the expert serves ``prompt`` and it names the expert's ``mirror_side`` alone."""
        return self.mirror_side is not None and self.serves(prompt) and sides(prompt) == {self.mirror_side}

    @classmethod
    def from_entry(cls, entry: Mapping, state: dict[str, torch.Tensor], main: Denoiser, where: str) -> ActionExpert:
        """The expert of a checkpoint.json ``entry`` with weights ``state``, for the main network ``main``;
        an entry without actions, weights that do not fit the main network's architecture or statistics
        are a one-line `KinemaError` naming ``where``."""
        if not isinstance(entry, Mapping) or not isinstance(entry.get("actions"), list):
            raise KinemaError(f"{where}: expected an object with a list 'actions'")
        actions = expert_actions(entry["actions"], where)
        model = Denoiser(main.config)
        try:
            model.load_state_dict({k: v.float() for k, v in state.items()})
        except RuntimeError as err:
            raise KinemaError(f"{where}: the expert's weights do not fit the model's network ({err})") from None
        for name in ("feat_mean", "feat_std", "local_mean", "local_std"):
            if not torch.allclose(getattr(model, name), getattr(main, name)):
                raise KinemaError(f"{where}: the expert was trained in other feature statistics ({name}) "
                                  "than the model")
        for p in model.parameters():
            p.requires_grad_(False)
        return cls(actions, model.eval(), dict(entry), mirror_side(entry.get("mirror_side"), where))
