"""The rig panel: which character the tab shows (the model's skeleton, or a GLB/glTF/BVH rig uploaded
here or given with ``kinema app --rig FILE``), its clips, and whether its skin is drawn. A rig the
model cannot generate for is shown for playback, with a notification saying so (kinema.app.generation)."""

from __future__ import annotations

from kinema.app import generation as gen
from kinema.app.files_panel import UNITS
from kinema.app.rigs import load_rig_bytes, model_rig
from kinema.errors import KinemaError

NO_CLIP = "(rest pose)"


class RigPanel:
    """``host`` is the tab's Session (its rig, motions and notifications)."""

    def __init__(self, gui, host):
        self.host = host
        with gui.add_folder("Rig", expand_by_default=False):
            self.info = gui.add_markdown("")
            self.clip = gui.add_dropdown("Clip", (NO_CLIP,), hint="play one of the rig file's own animations")
            self.skin = gui.add_checkbox("Show skin", host.skin, hint="the rig's skinned mesh (else bones only)")
            upload = gui.add_upload_button(
                "Upload rig", icon="upload", hint="a .glb / .gltf rig with its skin and clips, or a .bvh"
            )
            self.back = gui.add_button("Use the model's skeleton", icon="user")
        self.back.visible = not gen.is_any_rig(host.model)
        self.clip.on_update(lambda _: self._clip())
        self.skin.on_update(lambda _: self._skin())
        upload.on_upload(lambda _: self._upload(upload.value.name, upload.value.content))
        self.back.on_click(lambda _: host.set_rig(model_rig(host.model.skeleton, name=host.app.model_name)))
        self.refresh()

    def refresh(self) -> None:
        rig = self.host.rig
        names = tuple(rig.clips) or (NO_CLIP,)
        self._updating = True
        self.clip.options = names
        self.clip.value = names[0]
        self.clip.disabled = not rig.clips
        self.skin.value = self.host.skin
        self._updating = False
        self.info.content = (
            f"**{rig.name}**: {rig.skeleton.num_joints} joints, {rig.mesh.num_vertices} skin vertices, "
            f"{len(rig.contacts)} contact joints, {len(rig.clips)} clip(s)"
        )

    def select(self, name: str) -> None:
        """Show ``name`` in the Clip dropdown (the session shows the clip itself)."""
        self._updating = True
        self.clip.value = name
        self._updating = False

    def _clip(self) -> None:
        if not self._updating and self.clip.value in self.host.rig.clips:
            self.host.show_clip(self.clip.value)

    def _skin(self) -> None:
        if not self._updating and bool(self.skin.value) != self.host.skin:
            self.host.skin = bool(self.skin.value)
            self.host.redraw()

    def _upload(self, name: str, content: bytes) -> None:
        scale = UNITS[self.host.files.units.value]
        try:
            rig = load_rig_bytes(name, content, fps=self.host.model.fps, scale=scale)
        except KinemaError as err:
            self.host.notify("Upload failed", str(err), error=True)
            return
        self.host.set_rig(rig)
        self.host.notify("Rig loaded", f"{name}: {rig.skeleton.num_joints} joints")
