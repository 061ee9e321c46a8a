"""Captions for keyframed creature clips (Quaternius packs) from the file name and the clip name.

A Quaternius GLB is named after its character (``Fox.glb``, ``Trex.glb``, ``KnightCharacter.glb``)
and its animations after what they do, with authoring noise: an armature prefix
(``AnimalArmature|Gallop``), Blender's duplicate suffix (``Swim.001``), a species prefix that is
sometimes another species' (``Armature|Stegosaurus_Death`` in ``Apatosaurus.glb``), numbered
variants (``HitRecieve_2``), misspellings (``HitRecieve``) and mixed casing (``swordAttackJump``).

`clean_clip_name` reduces a clip name to an *action key* such as ``hit_receive`` or
``idle_hit_react_left``; `subject_for` turns a file into a noun phrase ("fox", "T-rex", "knight");
`creature_captions` combines them into a few short present-tense sentences ("A fox gallops.",
"The fox runs at a gallop."). Props (a chest that opens, a lever) are flagged by `is_prop` so
that a trainer can exclude them. Everything is deterministic so caches and tests are stable.
"""

from __future__ import annotations

import re
from pathlib import PurePath

#: Misspellings found in the shared files -> the correct word (compared case-insensitively).
MISSPELLINGS = {"recieve": "receive", "recieved": "received"}
#: Words that are the same action under another name.
SYNONYMS = {"walking": "walk", "dead": "death", "swimming": "swim", "headlow": "head_low"}
#: Species or prop words that prefix some clip names (``TRex_Walk``, ``Lever_On``); stripped.
NAME_PREFIXES = frozenset(
    "trex t_rex apatosaurus stegosaurus parasaurolophus triceratops frog rat snake wasp bouncer chest lever "
    "spike_trap spiketrap".split()
)
#: Files (stem, lower case) that are props, not creatures: their clips are flagged ``prop``.
PROP_FILES = frozenset({"chest", "lever", "hazard_spiketrap", "bouncer"})
#: Action keys that only props perform.
PROP_ACTIONS = frozenset({"open", "close", "on", "off", "activate", "bounce"})

#: Subject nouns for files whose stem does not read as English on its own (lower-case stem ->
#: noun). Other stems are split at capitals and underscores: ``BlueTang`` -> "blue tang".
SUBJECTS = {
    "trex": "T-rex",
    "shibainu": "Shiba Inu",
    "horse_white": "white horse",
    "manta_ray": "manta ray",
    "fish1": "fish",
    "fish2": "fish",
    "fish3": "fish",
    "humphead": "humphead wrasse",
    "puffer": "pufferfish",
    "flowerhorn": "flowerhorn fish",
    "parrotfish": "parrotfish",
    "zebraclownfish": "zebra clownfish",
    "snake_angry": "angry snake",
    "knightcharacter": "knight",
    "character": "person",
    "character_gun": "person",
    "george": "robot",
    "mike": "robot",
    "stan": "robot",
    "enemy": "monster",
    "skull": "flying skull",
    "enemy_2legs": "two-legged robot",
    "enemy_2legs_gun": "two-legged robot",
    "enemy_flying": "flying drone",
    "enemy_flying_gun": "flying drone",
    "enemy_large": "large robot",
    "enemy_large_gun": "large robot",
    "enemy_extrasmall": "tiny flying alien",
    "enemy_small": "small flying alien",
    "hazard_spiketrap": "spike trap",
    "bouncer": "bounce pad",
}
#: Per-pack overrides where one stem means different things in different packs.
PACK_SUBJECTS = {
    ("ultimate_space_pack", "enemy_flying"): "flying alien",
    ("ultimate_space_pack", "enemy_large"): "large alien",
}
#: Prefixes of stems that name a character type followed by a name: ``Astronaut_FinnTheFrog``.
ROLE_PREFIXES = {"astronaut": "astronaut", "mech": "small mech"}

# Action key -> present-tense verb phrases (the first is the plainest). Sides are the character's own.
ACTIONS: dict[str, tuple[str, ...]] = {
    "walk": ("walks", "walks forward", "walks at a steady pace"),
    "walk_tall": ("walks tall", "walks upright with long steps"),
    "walk_holding": ("walks while carrying something", "walks holding an object"),
    "walk_gun": ("walks holding a gun", "walks with a gun in hand"),
    "run": ("runs", "runs forward", "runs quickly"),
    "run_back": ("runs backwards", "runs backward"),
    "run_left": ("runs to the left", "runs sideways to the left"),
    "run_right": ("runs to the right", "runs sideways to the right"),
    "run_tall": ("runs tall", "runs upright with long strides"),
    "run_holding": ("runs while carrying something", "runs holding an object"),
    "run_gun": ("runs holding a gun", "runs with a gun in hand"),
    "run_shoot": ("runs and shoots", "shoots while running"),
    "run_gun_shoot": ("runs and shoots a gun", "shoots a gun while running"),
    "run_sword_attack": ("runs and attacks with a sword", "swings a sword while running"),
    "run_sword_right": ("runs holding a sword in the right hand", "runs with a sword"),
    "gallop": ("gallops", "runs at a gallop", "gallops forward"),
    "gallop_jump": ("jumps while galloping", "leaps at a gallop"),
    "swim": ("swims", "swims forward", "swims steadily"),
    "swim_normal": ("swims", "swims at a normal pace", "swims steadily"),
    "swim_fast": ("swims fast", "swims quickly", "darts through the water"),
    "swim_impulse": ("swims in a quick burst", "gives a sudden push forward while swimming"),
    "flying": ("flies", "flies in place", "hovers in the air"),
    "fast_flying": ("flies fast", "flies quickly"),
    "flying_idle": ("hovers in the air", "flies in place"),
    "out_of_water": ("flops about out of the water", "struggles out of the water"),
    "idle": ("stands idle", "stands still", "waits in place"),
    "idle_neutral": ("stands idle", "stands still in a neutral pose"),
    "idle_head_low": ("stands idle with its head low", "stands still, head lowered"),
    "idle_gun": ("stands holding a gun", "waits with a gun in hand"),
    "idle_gun_pointing": ("stands pointing a gun", "aims a gun while standing"),
    "idle_gun_shoot": ("shoots a gun while standing", "stands and shoots a gun"),
    "idle_shoot": ("shoots while standing", "stands and shoots"),
    "idle_sword": ("stands holding a sword", "waits with a sword"),
    "idle_sword_left": ("stands holding a sword in the left hand", "waits with a sword in the left hand"),
    "idle_sword_right": ("stands holding a sword in the right hand", "waits with a sword in the right hand"),
    "idle_hit_react_left": ("flinches from a hit on the left", "is hit from the left"),
    "idle_hit_react_right": ("flinches from a hit on the right", "is hit from the right"),
    "hit_react": ("reacts to being hit", "flinches from a hit"),
    "hit_receive": ("gets hit", "reacts to being hit", "flinches from a blow"),
    "attack": ("attacks", "lunges forward to attack"),
    "attack_headbutt": ("attacks with a headbutt", "headbutts"),
    "attack_kick": ("kicks with its hind legs", "attacks with a kick"),
    "headbutt": ("headbutts", "attacks with a headbutt"),
    "bite_front": ("bites forward", "lunges forward and bites"),
    "bite_in_place": ("bites in place", "snaps its jaws without moving"),
    "punch": ("punches", "throws a punch"),
    "punch_left": ("punches with the left hand", "throws a left punch"),
    "punch_right": ("punches with the right hand", "throws a right punch"),
    "kick": ("kicks", "throws a kick"),
    "kick_left": ("kicks with the left leg", "throws a left kick"),
    "kick_right": ("kicks with the right leg", "throws a right kick"),
    "sword_slash": ("slashes with a sword", "swings a sword"),
    "sword_attack_jump": ("jumps and strikes with a sword", "leaps into a sword attack"),
    "shoot": ("shoots", "fires a weapon"),
    "gun_shoot": ("shoots a gun", "fires a gun"),
    "shoot_big": ("fires a big shot", "shoots a heavy weapon"),
    "shoot_small": ("fires a small shot", "shoots a light weapon"),
    "weapon": ("draws a weapon", "pulls out a weapon"),
    "jump": ("jumps", "jumps up", "leaps into the air"),
    "jump_idle": ("is in the air mid-jump", "hangs in the air during a jump"),
    "jump_land": ("lands from a jump", "lands on the ground"),
    "jump_landing": ("lands from a jump", "lands on the ground"),
    "jump_no_height": ("jumps without leaving the ground", "crouches and springs in place"),
    "jump_to_idle": ("lands from a jump and stands still", "lands and settles into standing"),
    "roll": ("rolls forward", "does a forward roll"),
    "roll_sword": ("rolls forward holding a sword", "does a forward roll with a sword"),
    "duck": ("ducks", "crouches down to dodge"),
    "death": ("dies", "collapses and dies", "falls down dead"),
    "eating": ("eats", "lowers its head to eat", "grazes"),
    "dance": ("dances", "does a little dance"),
    "wave": ("waves", "waves hello", "waves a hand"),
    "hello": ("waves hello", "greets with a wave"),
    "yes": ("nods yes", "agrees with a nod"),
    "no": ("shakes its head no", "refuses with a shake of the head"),
    "pickup": ("picks something up", "bends down to pick something up"),
    "interact": ("reaches out to interact with something", "presses something in front of it"),
    "open": ("opens", "swings open"),
    "close": ("closes", "swings shut"),
    "on": ("is switched on", "flips on"),
    "off": ("is switched off", "flips off"),
    "activate": ("springs its spikes", "activates"),
    "bounce": ("bounces", "springs up and down"),
}
#: Locomotion actions: every Quaternius clip of these is animated in place (root does not travel).
LOCOMOTION = frozenset(k for k in ACTIONS if k.split("_")[0] in {"walk", "run", "gallop", "swim"})


def _words(text: str) -> list[str]:
    """Lower-case words of a CamelCase/snake_case name: ``swordAttackJump`` -> sword, attack, jump."""
    text = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", text)
    text = re.sub(r"([A-Z]+)([A-Z][a-z])", r"\1 \2", text)
    return [w.lower() for w in re.split(r"[\s_\-]+", text) if w]


def clean_clip_name(name: str) -> str:
    """Action key of a clip name: armature prefix, ``.001`` suffix, species prefix and variant
    number stripped, misspellings fixed, words lower-case and joined by ``_``.

    ``AnimalArmature|Idle_HitReact_Left`` -> ``idle_hit_react_left``; ``Armature|TRex_Walk`` ->
    ``walk``; ``CharacterArmature|HitRecieve_2`` -> ``hit_receive``; ``Armature|Swim.001`` -> ``swim``;
    ``Fish_Armature|Swimming_Fast`` -> ``swim_fast``; ``Jump_ToIdle`` -> ``jump_to_idle``.
    """
    base = name.rsplit("|", 1)[-1]
    base = re.sub(r"\.\d+$", "", base)
    words = [MISSPELLINGS.get(w, w) for w in _words(base)]
    while words and words[-1].isdigit():
        words.pop()
    words = [SYNONYMS.get(w, w) for w in words]
    key = "_".join(words)
    for prefix in sorted(NAME_PREFIXES, key=len, reverse=True):
        if key.startswith(prefix + "_") and len(key) > len(prefix) + 1:
            key = key[len(prefix) + 1 :]
            break
    key = re.sub(r"_\d+(?=_|$)", "", key)  # Idle_2_HeadLow -> idle_head_low
    return key or "_".join(words)


def _stem(path: str | PurePath) -> str:
    """File stem without ``.glb``/``.bvh`` and the ``-transformed`` tag of the space pack."""
    stem = PurePath(str(path)).name
    stem = re.sub(r"\.(glb|gltf|bvh)(\.gz)?$", "", stem, flags=re.IGNORECASE)
    return re.sub(r"-transformed$", "", stem)


def subject_for(path: str | PurePath) -> str:
    """Noun phrase naming the character of a file: ``animals_pack/Fox.glb`` -> "fox",
    ``dinosaurs_pack/Trex.glb`` -> "T-rex", ``Astronaut_FinnTheFrog-transformed.glb`` -> "astronaut"."""
    p = PurePath(str(path))
    stem = _stem(p).lower()
    pack = p.parent.name.lower()
    if (pack, stem) in PACK_SUBJECTS:
        return PACK_SUBJECTS[(pack, stem)]
    if stem in SUBJECTS:
        return SUBJECTS[stem]
    head = stem.split("_", 1)[0]
    if head in ROLE_PREFIXES and "_" in stem:
        return ROLE_PREFIXES[head]
    return " ".join(_words(_stem(p)))


def is_prop(path: str | PurePath, action: str) -> bool:
    """Whether a clip animates a prop (chest, lever, spike trap, bounce pad) rather than a creature."""
    return _stem(path).lower() in PROP_FILES or action in PROP_ACTIONS


def _article(noun: str) -> str:
    return "An" if noun[:1].lower() in "aeiou" else "A"


def action_phrases(action: str) -> tuple[str, ...]:
    """Verb phrases for an action key; an unknown key reads as its words ("performs a tail whip")."""
    if action in ACTIONS:
        return ACTIONS[action]
    words = action.replace("_", " ").strip() or "motion"
    return (f"performs a {words} motion", f"does a {words} animation")


def creature_captions(path: str | PurePath, clip_name: str, *, in_place: bool = False) -> list[str]:
    """Captions for clip ``clip_name`` of file ``path``: one sentence per verb phrase, alternating
    "A fox ..." and "The fox ...", plus one that says "in place" for locomotion that does not travel.

    >>> creature_captions("animals_pack/Fox.glb", "AnimalArmature|Gallop")[0]
    'A fox gallops.'
    """
    noun = subject_for(path)
    action = clean_clip_name(clip_name)
    subjects = (f"{_article(noun)} {noun}", f"The {noun}")
    phrases = action_phrases(action)
    if in_place and action in LOCOMOTION:  # a clip animated on the spot does not go "forward"
        phrases = tuple(p for p in phrases if "forward" not in p) or phrases[:1]
    out = []
    for i, phrase in enumerate(phrases):
        out.append(f"{subjects[i % 2]} {phrase}.")
    if in_place and action in LOCOMOTION:  # "A robot runs in place." (the gait alone, not "while carrying")
        out.append(f"{subjects[0]} {ACTIONS[action.split('_')[0]][0]} in place.")
    return out
