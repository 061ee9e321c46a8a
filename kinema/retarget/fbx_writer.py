"""FBX writing through Blender: kinema writes the motion as GLB (kinema.io.gltf_writer, with the rig's
skin and materials) and Blender, run headless, imports it and exports FBX
(kinema/retarget/blender_fbx_script.py). Blender is found as ``blender`` on PATH (or the
``KINEMA_BLENDER`` environment variable); without it a one-line `KinemaError` says what to install.
Tested with Debian's Blender 3.4.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from kinema.errors import KinemaError
from kinema.io.gltf_writer import write_glb
from kinema.motion.core import Motion

SCRIPT = Path(__file__).with_name("blender_fbx_script.py")
TIMEOUT_S = 600


def find_blender() -> str | None:
    """The Blender executable (``KINEMA_BLENDER`` or ``blender`` on PATH), or None."""
    return os.environ.get("KINEMA_BLENDER") or shutil.which("blender")


def write_fbx(motion: Motion, path: str | os.PathLike, *, name: str = "motion") -> Path:
    """Write ``motion`` (on a rig, with its skin when it has one) as FBX through Blender; returns the path."""
    path = Path(path)
    blender = find_blender()
    if blender is None:
        raise KinemaError(
            f"{path}: writing FBX needs Blender (apt-get install blender python3-numpy, or set KINEMA_BLENDER); "
            "write .glb or .bvh instead"
        )
    with tempfile.TemporaryDirectory(prefix="kinema-fbx-") as tmp:
        glb = write_glb(motion, Path(tmp) / f"{name}.glb", name=name)
        out = Path(tmp) / "out.fbx"
        cmd = [blender, "-b", "--factory-startup", "--python", str(SCRIPT), "--", str(glb), str(out)]
        cmd.append(f"{motion.fps:.9g}")
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S)
        except (OSError, subprocess.TimeoutExpired) as err:
            raise KinemaError(f"{path}: Blender could not run ({err})") from None
        if proc.returncode != 0 or not out.is_file():
            last = (proc.stderr.strip().splitlines() or proc.stdout.strip().splitlines() or ["no output"])[-1]
            raise KinemaError(f"{path}: Blender's FBX export failed: {last}")
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(out), path)
    return path
