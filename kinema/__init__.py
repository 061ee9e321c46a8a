"""kinema: text- and constraint-driven skeletal motion generation for any rig.

Public API::

    import kinema
    model = kinema.load_model("default")          # or a run / checkpoint folder
    motions = model.generate("A person walks forward happily.", seconds=4)
    motions[0].save("walk.bvh")
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from kinema import io  # noqa: F401  (torch-free: registers the file formats Motion.save reaches)
from kinema.io import load_motion

__version__ = "0.1.0"
__all__ = ["load_model", "load_motion", "Motion", "Skeleton", "__version__"]

if TYPE_CHECKING:  # pragma: no cover
    from kinema.generate import load_model
    from kinema.motion.core import Motion
    from kinema.skeleton import Skeleton


def __getattr__(name: str):
    """Import lazily so that `import kinema` (and the CLI) start fast."""
    if name == "load_model":
        from kinema.generate import load_model

        return load_model
    if name == "Motion":
        from kinema.motion.core import Motion

        return Motion
    if name == "Skeleton":
        from kinema.skeleton import Skeleton

        return Skeleton
    raise AttributeError(f"module 'kinema' has no attribute {name!r}")
