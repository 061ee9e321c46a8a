"""Which Quaternius humanoid clips the human model learns, under which content label, and their captions.

The Quaternius characters (cyberpunk, platformer, astronauts, knight, mechs; CC0) carry keyframed game
animations of actions the Bandai Namco captures lack: kicks, punches, jumps, rolls, ducks, head nods and
shakes, dances, picking up, falling down. `HUMANOID_ACTIONS` maps a cleaned clip name
(kinema.data.creature_captions.clean_clip_name) to what it shows; locomotion, idles, weapon and hit
clips are left out on purpose (the captures hold far better walks and runs; the rest needs a prop or a
partner to read).

A clip's side (which leg kicks, which hand punches) is *measured* on the retargeted motion
(kinema.data.humanoid_clips.measured_side), not read from the name: a clip named ``Kick`` has no side
in its name, and a name could mean the viewer's left. Captions name the side the motion shows.

Captions: several phrasings per action, all naming the action in words kinema.model.actions reads, plus
one honest caption of style ("..., in the style of a video-game animation."): these are stylised,
keyframed game animations, not motion capture. `HELD_OUT_PROMPTS` are phrasings no caption uses, for
evaluating whether the model learned the action and not the sentence (tests/test_humanoid_actions.py
checks they are no training caption).
"""

from __future__ import annotations

from dataclasses import dataclass

from kinema.model.sides import mirror_caption

#: The style label of every humanoid clip (clips.json ``style``).
STYLE = "game-animation"
#: The style caption's tail, appended to the action's first phrasing.
STYLE_TAIL = ", in the style of a video-game animation."


@dataclass(frozen=True)
class HumanoidAction:
    """One action: its content label (``{side}`` filled in when ``sided``), its caption phrasings, which
    body part names the side (``"foot"``, ``"hand"``, or ``"fall"``: forward/backward), whether the source
    clip loops (then repeated, kinema.data.humanoid_clips.LOOP_SECONDS), what follows it (``"idle"`` or
    ``"hold"``: the last pose held, for falls)."""

    content: str
    phrasings: tuple[str, ...]
    sided: str | None = None
    loop: bool = False
    after: str = "idle"


_KICK = HumanoidAction(
    "kick-{side}",
    (
        "A person kicks with their {side} leg.",
        "Someone kicks with the {side} foot.",
        "A person does a high kick with the {side} leg.",
        "A person kicks forward with their {side} leg.",
    ),
    sided="foot",
)
_PUNCH = HumanoidAction(
    "punch-{side}",
    (
        "A person punches with their {side} hand.",
        "Someone throws a {side} punch.",
        "A person punches forward with the {side} fist.",
        "A person throws a punch with their {side} arm.",
    ),
    sided="hand",
)
_JUMP = HumanoidAction(
    "jump",
    ("A person jumps up.", "Someone jumps in the air.", "A person jumps high and lands.", "A person leaps up."),
)
_ROLL = HumanoidAction(
    "roll",
    ("A person rolls forward.", "Someone does a forward roll.", "A person tucks and rolls.",
     "A person rolls on the ground."),
)
_DUCK = HumanoidAction(
    "duck",
    ("A person ducks.", "Someone ducks down and stands back up.", "A person crouches down quickly.",
     "A person ducks down."),
)
_YES = HumanoidAction(
    "nod-yes",
    ("A person nods yes.", "Someone nods their head.", "A person nods in agreement.", "A person nods."),
)
_NO = HumanoidAction(
    "shake-head-no",
    ("A person shakes their head no.", "Someone shakes their head.", "A person shakes the head to say no.",
     "A person shakes their head in refusal."),
)
_DANCE = HumanoidAction(
    "dance",
    ("A person dances.", "Someone dances in place.", "A person dances to the music.", "A person does a little dance."),
    loop=True,
)
_PICKUP = HumanoidAction(
    "pick-up",
    ("A person picks something up from the ground.", "Someone bends down and picks up an object.",
     "A person picks an item up off the floor.", "A person bends over and picks something up."),
)
_FALL = HumanoidAction(
    "fall-{side}",  # side here is the direction of the fall: forward / backward (measured)
    ("A person falls {side} to the ground.", "Someone collapses and falls {side}.", "A person falls down {side}.",
     "A person falls over {side} and lies still."),
    sided="fall",
    after="hold",
)

#: cleaned clip name -> (action, the cleaned names chained to make the clip).
HUMANOID_ACTIONS: dict[str, tuple[HumanoidAction, tuple[str, ...]]] = {
    "kick_left": (_KICK, ("kick_left",)),
    "kick_right": (_KICK, ("kick_right",)),
    "kick": (_KICK, ("kick",)),
    "punch_left": (_PUNCH, ("punch_left",)),
    "punch_right": (_PUNCH, ("punch_right",)),
    "punch": (_PUNCH, ("punch",)),
    "jump": (_JUMP, ("jump", "jump_idle", "jump_land")),
    "roll": (_ROLL, ("roll",)),
    "duck": (_DUCK, ("duck",)),
    "yes": (_YES, ("yes",)),
    "no": (_NO, ("no",)),
    "dance": (_DANCE, ("dance",)),
    "pickup": (_PICKUP, ("pickup",)),
    "death": (_FALL, ("death",)),
}
#: Idle clips (cleaned names, in order of preference) that pad an action before and after.
IDLE_NAMES = ("idle_neutral", "idle")

#: Phrasings no training caption uses, per content, for evaluating the learned actions.
HELD_OUT_PROMPTS: dict[str, tuple[str, ...]] = {
    "kick-left": ("Someone delivers a kick with the left foot.", "A man kicks hard using his left leg."),
    "kick-right": ("Someone delivers a kick with the right foot.", "A man kicks hard using his right leg."),
    "punch-left": ("A man punches straight ahead with his left fist.", "Someone jabs with the left hand."),
    "punch-right": ("A man punches straight ahead with his right fist.", "Someone jabs with the right hand."),
    "jump": ("A man jumps straight up into the air.", "Someone hops up off the ground."),
    "roll": ("A man rolls forward across the floor.", "Someone performs a roll."),
    "fall": ("A man falls down onto the floor.", "Someone trips and falls over."),
    "nod-yes": ("A man nods his head in agreement.", "Someone nods to say yes."),
    "nod-no": ("A man shakes his head in refusal.", "Someone shakes their head to say no."),
}


def side_word(action: HumanoidAction, side: str | None) -> str:
    """The word filled in for ``{side}``: left/right for kicks and punches, forward/backward for falls."""
    if action.sided is None:
        return ""
    if side is None:
        raise ValueError(f"{action.content}: a {action.sided} side is needed")
    return side


def content_label(action: HumanoidAction, side: str | None) -> str:
    """The clip's content label, e.g. ``kick-left`` or ``jump``."""
    return action.content.format(side=side_word(action, side))


def humanoid_captions(action: HumanoidAction, side: str | None, *, mirrored: bool = False) -> list[str]:
    """The clip's captions: every phrasing, then the style caption. ``side`` is the measured side of the
    clip as built; a mirrored copy's captions are mirrored with it (left <-> right)."""
    word = side_word(action, side)
    lines = [p.format(side=word) for p in action.phrasings]
    lines.append(lines[0].rstrip(".") + STYLE_TAIL)
    if mirrored:
        lines = [mirror_caption(c) for c in lines]
    return lines
