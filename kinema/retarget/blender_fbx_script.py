"""Runs inside Blender (not imported by kinema): convert a GLB written by kinema into FBX.

    blender -b --factory-startup --python blender_fbx_script.py -- IN.glb OUT.fbx FPS

Sets the scene's frame rate to FPS (so the glTF importer keys every motion frame on a frame of
its own), imports the GLB with Blender's own glTF importer (armature, skinned mesh, materials, every clip as an
action), then exports FBX with the armature's deform bones, the mesh and the baked animation. Debian's
Blender 3.4 glTF importer uses ``numpy.bool``, which numpy 1.24+ removed: the script restores it.
Exit status 3 with a one-line message on stderr when the import or export fails.
"""

from __future__ import annotations

import sys

import numpy

if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Blender 3.4's glTF importer still uses the old alias

import bpy  # noqa: E402


def main(argv: list[str]) -> None:
    src, out, fps = argv[0], argv[1], float(argv[2])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = max(1, round(fps))
    scene.render.fps_base = scene.render.fps / fps
    bpy.ops.import_scene.gltf(filepath=src)
    arm = next((o for o in bpy.data.objects if o.type == "ARMATURE"), None)
    if arm is None:
        sys.stderr.write(f"{src}: Blender found no armature\n")
        sys.exit(3)
    actions = list(bpy.data.actions)
    if actions:
        if arm.animation_data is None:
            arm.animation_data_create()
        arm.animation_data.action = actions[0]
        start, end = actions[0].frame_range
        scene.frame_start, scene.frame_end = int(start), int(round(end))
    bpy.ops.export_scene.fbx(
        filepath=out,
        object_types={"ARMATURE", "MESH"},
        add_leaf_bones=False,
        bake_anim=bool(actions),
        bake_anim_use_all_actions=False,
        bake_anim_use_nla_strips=False,
        bake_anim_simplify_factor=0.0,
        axis_forward="-Z",
        axis_up="Y",
    )


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1 :])
