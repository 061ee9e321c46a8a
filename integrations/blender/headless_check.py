"""Run the kinema add-on inside a headless Blender against a running server and report what was imported.

    blender -b --factory-startup --python integrations/blender/headless_check.py \
        -- URL API_KEY PROMPT SECONDS STEPS OUT.json

Registers the add-on from this folder (no installation), sets its preferences and scene settings, runs
the same operator the sidebar button runs, and writes ``{"armature", "bones", "frame_range", "result"}``
to OUT.json; exits non-zero when the operator fails (tests/test_server.py runs it when Blender exists).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import addon_utils
import bpy

sys.path.insert(0, str(Path(__file__).resolve().parent))  # kinema_blender is importable from here


def main(argv: list[str]) -> int:
    url, key, prompt, seconds, steps, out = argv
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # enabled the way Preferences > Add-ons does it, so that the add-on has its preferences entry
    mod = addon_utils.enable("kinema_blender", default_set=True, handle_error=None)
    if mod is None:
        raise RuntimeError("the kinema_blender add-on could not be enabled")
    addon = bpy.context.preferences.addons["kinema_blender"]
    addon.preferences.server, addon.preferences.api_key = url, key
    s = bpy.context.scene.kinema
    s.prompt, s.seconds, s.steps = prompt, float(seconds), int(steps)
    result = bpy.ops.kinema.generate()
    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    report = {"result": sorted(result), "armature": arms[0].name if arms else None,
              "bones": [b.name for b in arms[0].data.bones] if arms else [],
              "frame_range": list(arms[0].animation_data.action.frame_range) if arms else None,
              "prompt": arms[0].get("kinema_prompt") if arms else None}
    Path(out).write_text(json.dumps(report))
    return 0 if "FINISHED" in result and arms else 1


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    sys.exit(main(args))
