"""Fixed generation cases on the shipped human model whose outputs are recorded in
tests/data/reference_outputs.npz (by scripts/record_reference_outputs.py, from the code before the
rig/representation refactor of issue 14) and compared by tests/test_reference_outputs.py.
`creature_cases` are the any-rig "creatures" model's cases on a Quaternius rig from the shared data
(tests/data/reference_outputs_creatures.npz, recorded by the same script with ``--creatures``).

Each case is ``(name, prompt_or_timeline, kwargs)``; keyframe poses are stored in the fixture itself
(``input_kf_rot (K, J, 3)`` axis-angle, ``input_kf_root (K, 3)`` metres) so the case does not depend on
the code under test.
"""

from __future__ import annotations

import numpy as np

STEPS = 5

HANDS = [
    {"type": "right-hand", "times": [1.0], "positions": [[-0.2, 1.2, 0.5]]},
    {
        "type": "left-hand",
        "times": [2.0],
        "positions": [[0.35, 0.9, 0.6]],
        "rotations": [[0.0, 0.0, 1.2]],
        "smooth_root_2d": [[0.1, 0.6]],
    },
    {"type": "foot-contact", "times": [0.5, 1.0], "contacts": [[1, 1, 1, 1], [1, 1, 0, 0]]},
]
WAYPOINTS = [
    {"type": "root2d", "times": [1.0, 2.0], "smooth_root_2d": [[0.0, 1.0], [0.5, 2.0]]},
    {"type": "root2d", "times": [2.4], "smooth_root_2d": [[0.7, 2.2]], "global_root_heading": [[0.0, 1.0]]},
]
TIMELINE = [{"prompt": "A person bows.", "seconds": 1.5}, {"prompt": "A person walks forward.", "seconds": 1.5}]


def keyframes(kf_rot: np.ndarray, kf_root: np.ndarray) -> list[dict]:
    """Two full-body keyframes (frames 0 and 30) from stored poses."""
    return [
        {
            "type": "fullbody",
            "frame_indices": [0, 30],
            "local_joints_rot": kf_rot.tolist(),
            "root_positions": kf_root.tolist(),
        }
    ]


def cases(kf_rot: np.ndarray, kf_root: np.ndarray) -> list[tuple[str, object, dict]]:
    base = {"steps": STEPS, "seed": 3}
    out = []
    for post in (False, True):
        tag = "post" if post else "raw"
        out += [
            (f"text_{tag}", "A person walks forward.", {**base, "seconds": 2.5, "samples": 2, "postprocess": post}),
            (
                f"keyframes_{tag}",
                "A person walks forward.",
                {**base, "seconds": 2.0, "constraints": keyframes(kf_rot, kf_root), "postprocess": post},
            ),
            (
                f"hands_{tag}",
                "A person raises their right hand.",
                {**base, "seconds": 2.5, "constraints": HANDS, "postprocess": post},
            ),
            (
                f"waypoints_{tag}",
                "A person walks forward.",
                {**base, "seconds": 2.5, "constraints": WAYPOINTS, "postprocess": post},
            ),
            (f"timeline_{tag}", TIMELINE, {**base, "postprocess": post}),
        ]
    return out


#: the creatures cases' rig, below the shared datasets folder (a test-split file of the creatures model)
CREATURE_RIG = "quaternius/animals_pack/Alpaca.glb"
#: a root path over the second second and the head at a point at frame 10 (character-frame JSON, rig metres)
CREATURE_CONSTRAINTS = [
    {"type": "root_path", "frames": [20, 39], "xz": [[0.0, 0.6], [0.3, 1.2]]},
    {"type": "joint", "joint": "Head", "frame": 10, "position": [0.0, 1.8, 0.5]},
]


def creature_cases(rig: str) -> list[tuple[str, object, dict]]:
    """Prompt only, and a root path plus a joint target, on ``rig`` (a GLB path): 2 s, 5 steps."""
    base = {"steps": STEPS, "seed": 3, "seconds": 2.0, "rig": rig}
    return [
        ("creatures_text", "An alpaca walks forward.", base),
        ("creatures_constrained", "An alpaca walks forward.", {**base, "constraints": CREATURE_CONSTRAINTS}),
    ]
