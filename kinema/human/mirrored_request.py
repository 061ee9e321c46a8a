"""Requests generated as their mirror image, for a model whose action expert does one side worse.

Why (issue 38, docs/training.md "Stop 56"): every training clip of the human model is there twice, as
made and mirrored left to right with its caption's sides swapped, so in the data a right kick is exactly
the mirror image of a left kick. The action expert learned one side better all the same (the shipped
one, probed on held-out phrasings at 4 s: left kicks 12 of 12, right 5 of 12; at 5 s left punches 6 of
12, right none). A model whose expert names a ``mirror_side`` (kinema.model.action_expert) therefore
makes a request whose expert prompt names that side alone as the mirror image of the request for the
other side: every prompt's side words swapped (kinema.model.sides.mirror_caption), the heading negated,
and the raw motions mirrored back (kinema.motion.mirror) before post-processing. Prompts that name no side
("A person walks forward.") stay as they are: the mirror of their training data is their training data.

A request is mirrored only when that maps it onto itself exactly: no constraints or objectives (they are
placed in the user's frame, on named joints), at least one prompt the expert mirrors and no prompt naming
the other side. The report says which prompts were made as a mirror image, and of what.
"""

from __future__ import annotations

from kinema.model.action_expert import ActionExpert
from kinema.model.sides import mirror_caption, sides


def mirrored_prompts(prompts: list[str], expert: ActionExpert | None, constrained: bool) -> dict[str, str]:
    """``{prompt: the prompt it is made as}`` for a request of ``prompts`` (a timeline's, in order) to be
    generated as its mirror image, or ``{}`` when it is made as it is: no expert or no ``mirror_side``,
    ``constrained`` (constraints or objectives given), no prompt the expert mirrors, or a prompt naming
    the other side."""
    if expert is None or expert.mirror_side is None or constrained:
        return {}
    if not any(expert.mirrors(p) for p in prompts) or any(sides(p) - {expert.mirror_side} for p in prompts):
        return {}
    return {p: mirror_caption(p) for p in prompts}
