"""kinema for Blender: type a prompt in the 3D view's sidebar, get an animated armature.

The add-on sends the prompt to a running ``kinema serve`` (URL and API key in the add-on's preferences),
receives BVH text and imports it with Blender's own BVH importer (metres, Y up, as kinema writes it).
Install: zip the ``kinema_blender`` folder, then Edit > Preferences > Add-ons > Install. Headless use
and the tests: ``integrations/blender/headless_check.py``. Debian's Blender 3.4 runs Python 3.11,
whose ``open`` rejects the ``'rU'`` mode its BVH importer uses; `import_bvh_text` drops the ``U`` for
the importer's module only, for the duration of the import.
"""

from __future__ import annotations

import builtins
import os
import tempfile

import bpy

from .client import KinemaClientError, generate_bvh

bl_info = {
    "name": "kinema motion generation",
    "author": "kinema",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > kinema",
    "description": "Generate skeletal motion from text with a kinema server and import it as BVH",
    "category": "Animation",
}


def _open_without_u(file, mode="r", *args, **kwargs):
    """``open`` accepting the removed ``'U'`` flag (newline handling is the same without it)."""
    if isinstance(mode, str) and "U" in mode:
        mode = mode.replace("U", "") or "r"
    return builtins.open(file, mode, *args, **kwargs)


def import_bvh_text(text: str, name: str = "kinema_motion"):
    """Import BVH text as a new armature (returned); the temporary file is removed afterwards."""
    from io_anim_bvh import import_bvh

    fd, path = tempfile.mkstemp(prefix=f"{name}_", suffix=".bvh")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    before = set(bpy.data.objects)
    import_bvh.open = _open_without_u  # module global shadows the builtin inside the importer only
    try:
        result = bpy.ops.import_anim.bvh(filepath=path, target="ARMATURE", global_scale=1.0, rotate_mode="NATIVE",
                                         axis_forward="-Z", axis_up="Y", frame_start=1, use_fps_scale=False,
                                         update_scene_fps=True, update_scene_duration=True)
    finally:
        del import_bvh.open
        os.unlink(path)
    if "FINISHED" not in result:
        raise RuntimeError(f"BVH import failed: {result}")
    return next(o for o in bpy.data.objects if o not in before and o.type == "ARMATURE")


class KinemaPreferences(bpy.types.AddonPreferences):
    bl_idname = __name__
    server: bpy.props.StringProperty(name="Server", default="http://127.0.0.1:8000")
    api_key: bpy.props.StringProperty(name="API key", default="", subtype="PASSWORD")

    def draw(self, context):
        self.layout.prop(self, "server")
        self.layout.prop(self, "api_key")


class KinemaSettings(bpy.types.PropertyGroup):
    prompt: bpy.props.StringProperty(name="Prompt", default="A person walks forward.")
    seconds: bpy.props.FloatProperty(name="Seconds", default=4.0, min=0.1, max=120.0)
    steps: bpy.props.IntProperty(name="Steps", default=0, min=0, max=1000, description="0 = the model's default")
    seed: bpy.props.IntProperty(name="Seed", default=0, min=0)
    model: bpy.props.StringProperty(name="Model", default="", description="a served model's name ('' = the first)")
    rig: bpy.props.StringProperty(name="Rig", default="",
                                  description="a rig id from GET /v1/models ('' = the model's own skeleton)")


class KINEMA_OT_generate(bpy.types.Operator):
    """Generate a motion with the kinema server and import it as an armature"""

    bl_idname = "kinema.generate"
    bl_label = "Generate motion"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        prefs = context.preferences.addons[__name__].preferences
        s = context.scene.kinema
        try:
            text, report = generate_bvh(prefs.server, prompt=s.prompt, seconds=s.seconds, steps=s.steps, seed=s.seed,
                                        api_key=prefs.api_key, model=s.model, rig=s.rig)
            arm = import_bvh_text(text)
        except (KinemaClientError, RuntimeError) as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        arm["kinema_prompt"] = s.prompt
        for warning in report.get("warnings", []):
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"kinema: {report.get('frames', '?')} frames imported as {arm.name}")
        return {"FINISHED"}


class KINEMA_PT_panel(bpy.types.Panel):
    bl_label = "kinema"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "kinema"

    def draw(self, context):
        s = context.scene.kinema
        for prop in ("prompt", "seconds", "steps", "seed", "model", "rig"):
            self.layout.prop(s, prop)
        self.layout.operator(KINEMA_OT_generate.bl_idname)


CLASSES = (KinemaPreferences, KinemaSettings, KINEMA_OT_generate, KINEMA_PT_panel)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.kinema = bpy.props.PointerProperty(type=KinemaSettings)


def unregister():
    del bpy.types.Scene.kinema
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
