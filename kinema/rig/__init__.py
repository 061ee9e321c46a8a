"""Rigs: a skeleton plus its root joint, up/forward axes, contact joints, end effectors and limbs.

- kinema.rig.core: `Rig` (``Rig.from_skeleton(skeleton, overrides=...)``, ``to_dict`` / ``from_dict``);
- kinema.rig.find: finding the parts from joint names or the rest-pose geometry;
- kinema.rig.overrides: the small JSON that overrides what was found.
"""

from kinema.rig.core import Rig
from kinema.rig.overrides import OVERRIDE_KEYS

__all__ = ["OVERRIDE_KEYS", "Rig"]
