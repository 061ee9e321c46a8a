"""Import a GLB with Blender's own glTF importer and dump every bone's world head position at given times.

The Blender half of tests/test_gltf_blender.py; it runs inside Blender:

    blender -b --factory-startup --python scripts/blender_gltf_check.py -- IN.glb OUT.json CLIP TIMES

TIMES is a comma-separated list of seconds. The script imports the file, gives the armature the action
the importer made for animation CLIP, and for each time sets the scene to that frame (with a subframe,
at the scene's frame rate) and writes the heads of all pose bones in Blender world space (Z up:
Blender ``(x, y, z)`` = glTF ``(x, -z, y)``) together with the mesh's vertex count.

Debian's Blender 3.4 importer uses ``numpy.bool``, which numpy 1.24+ removed: the script restores it.
"""

from __future__ import annotations

import json
import sys

import numpy

if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Blender 3.4's glTF importer still uses the old alias

import bpy  # noqa: E402


def _action_for(clip: str):
    """The action Blender made for glTF animation ``clip`` (it may add an object-name suffix)."""
    actions = list(bpy.data.actions)
    for a in actions:
        if a.name == clip:
            return a
    hits = sorted((a for a in actions if a.name.startswith(clip + "_")), key=lambda a: len(a.name))
    if not hits:
        raise SystemExit(f"no action for clip {clip!r}; actions: {[a.name for a in actions]}")
    return hits[0]


def main(argv: list[str]) -> None:
    src, out, clip, times = argv[0], argv[1], argv[2], [float(t) for t in argv[3].split(",")]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=src)
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    if arm.animation_data is None:
        arm.animation_data_create()
    arm.animation_data.action = _action_for(clip)
    for track in arm.animation_data.nla_tracks:  # the importer parks the other clips here
        track.mute = True
    scene = bpy.context.scene
    fps = scene.render.fps / scene.render.fps_base
    heads = []
    for t in times:
        f = t * fps
        scene.frame_set(int(f), subframe=f - int(f))
        heads.append({b.name: list(arm.matrix_world @ b.head) for b in arm.pose.bones})
    report = {
        "bones": [b.name for b in arm.pose.bones],
        "heads": heads,
        "vertices": sum(len(m.data.vertices) for m in meshes),
        "skinned": all(any(mod.type == "ARMATURE" for mod in m.modifiers) for m in meshes) and bool(meshes),
    }
    with open(out, "w") as fh:
        json.dump(report, fh)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1 :])
