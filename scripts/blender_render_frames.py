"""Render frames of a GLB with its skinned mesh in Blender (Cycles on the CPU, headless), for pictures.

    blender -b --factory-startup --python scripts/blender_render_frames.py -- IN.glb OUT_PREFIX FPS FRAMES

FRAMES is a comma-separated list of frame numbers (at FPS); each is written to OUT_PREFIX_NNN.png.
The camera looks at the character from the front-left at hip height, from a distance set by the
mesh's height, following it as it walks; a sun and a plain grey-blue world light it. Debian's Blender
3.4 glTF importer needs ``numpy.bool``, restored here; its Cycles has no denoiser, so none is used.
"""

from __future__ import annotations

import math
import sys

import numpy

if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Blender 3.4's glTF importer still uses the old alias

import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402


def _setup(fps: float):
    scene = bpy.context.scene
    scene.render.fps = max(1, round(fps))
    scene.render.fps_base = scene.render.fps / fps
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 3.5
    sun.rotation_euler = (0.6, 0.3, 0.9)
    scene.collection.objects.link(sun)
    scene.world = bpy.data.worlds.new("white")
    scene.world.color = (0.45, 0.5, 0.56)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 24
    scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = 320, 420
    return scene, cam


def _height(meshes) -> float:
    zs = [(m.matrix_world @ Vector(c)).z for m in meshes for c in m.bound_box]
    return max(zs) - min(zs) if zs else 1.8


def main(argv: list[str]) -> None:
    src, prefix, fps, frames = argv[0], argv[1], float(argv[2]), [int(f) for f in argv[3].split(",")]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene, cam = _setup(fps)
    bpy.ops.import_scene.gltf(filepath=src)
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    height = _height(meshes)
    for f in frames:
        scene.frame_set(f)
        heads = [arm.matrix_world @ b.head for b in arm.pose.bones]
        centre = Vector([sorted(h[k] for h in heads)[len(heads) // 2] for k in range(3)])  # median: robust
        centre.z = 0.5 * height
        cam.location = centre + Vector((1.2, -1.9, 0.3)) * height  # front-left (glTF +Z is Blender -Y)
        d = centre - cam.location
        cam.rotation_euler = (math.atan2(math.hypot(d.x, d.y), -d.z), 0.0, math.atan2(d.y, d.x) - math.pi / 2)
        scene.render.filepath = f"{prefix}_{f:03d}.png"
        bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1 :])
