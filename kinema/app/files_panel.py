"""The files panel: download the shown motion (BVH, npz, GLB with the rig's skin) and the session
(timeline + constraints JSON), load a session again, and upload a BVH clip to in-between from (it
becomes the shown motion: scrub it and "Keyframe pose" the frames to keep). Uploads are parsed from a
private temporary folder and never written anywhere else; errors become notifications."""

from __future__ import annotations

import tempfile
import traceback
from pathlib import Path

from kinema.app.rigs import model_rig
from kinema.constraints.io import poses_from_bvh
from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat
from kinema.io.bvh import read_bvh
from kinema.motion.core import Motion

#: BVH length units -> scale to metres
UNITS = {"centimetres": 0.01, "metres": 1.0, "inches": 0.0254}
MOTION_SUFFIXES = (".bvh", ".bvh.gz")


def motion_bytes(motion: Motion, suffix: str) -> bytes:
    """The motion as a ``.bvh`` or ``.npz`` file's bytes (written by Motion.save to a temporary file)."""
    with tempfile.TemporaryDirectory(prefix="kinema-app-") as tmp:
        path = Path(tmp) / f"motion{suffix}"
        motion.save(path)
        return path.read_bytes()


def clip_on_model(name: str, content: bytes, *, skeleton, fps: float, scale: float) -> Motion:
    """An uploaded BVH clip on the model skeleton at the model fps (joints matched by name, first pose
    recentred over the origin), so its poses can be keyframed."""
    if not name.lower().endswith(MOTION_SUFFIXES):
        raise KinemaError(f"{name}: upload a .bvh or .bvh.gz motion")
    with tempfile.TemporaryDirectory(prefix="kinema-app-") as tmp:
        path = Path(tmp) / Path(name).name
        path.write_bytes(content)
        try:
            frames = read_bvh(path, scale=scale).resample(fps).num_frames
            rots, root = poses_from_bvh(
                path, list(range(frames)), skeleton=skeleton, fps=fps, scale=scale, recenter=True
            )
        except KinemaError as err:
            raise KinemaError(str(err).replace(str(path), name)) from None
    return Motion(skeleton, fps, root.float(), axis_angle_to_quat(rots).float())


class FilesPanel:
    """``host`` is the tab's Session (shown motion, document, notifications, loading)."""

    def __init__(self, gui, host):
        self.host = host
        with gui.add_folder("Files", expand_by_default=False):
            bvh = gui.add_button("Download BVH", icon="download")
            npz = gui.add_button("Download npz", icon="download")
            glb = gui.add_button("Download GLB", icon="download", hint="the shown motion with the rig's skin")
            session = gui.add_button(
                "Download session", icon="download", hint="timeline + constraints + settings as JSON"
            )
            load = gui.add_upload_button("Load session", icon="upload", mime_type="application/json")
            self.units = gui.add_dropdown("BVH units", tuple(UNITS), initial_value="centimetres")
            clip = gui.add_upload_button(
                "Upload BVH clip", icon="upload", hint="a motion on the model's skeleton to in-between from"
            )
        bvh.on_click(lambda e: self._download(e.client, ".bvh"))
        npz.on_click(lambda e: self._download(e.client, ".npz"))
        glb.on_click(lambda e: self._download(e.client, ".glb"))
        session.on_click(
            lambda e: e.client.send_file_download(
                "kinema_session.json", host.doc.to_json(host.model.fps).encode("utf-8"), save_immediately=True
            )
        )
        load.on_upload(lambda e: self._guard(lambda: host.load_session(load.value.name, load.value.content)))
        clip.on_upload(lambda e: self._guard(lambda: self._clip(clip.value.name, clip.value.content)))

    def _guard(self, fn) -> None:
        """Run an upload's handler; any failure is one line in a notification (nothing half-applied)."""
        try:
            fn()
        except KinemaError as err:
            self.host.notify("Upload failed", str(err), error=True)
        except Exception as err:  # a bug: the page says so in one line, the server log has the traceback
            traceback.print_exc()
            self.host.notify("Upload failed (internal error)", f"{type(err).__name__}: {err}", error=True)

    def _download(self, client, suffix: str) -> None:
        motion = self.host.result_motion()
        if motion is None:
            self.host.notify("Nothing to download", "generate a motion first", error=True)
            return
        rig = self.host.rig
        if suffix == ".glb":  # the rig's skin (a GLB file's own, else kinema's bone mesh) travels with it
            mesh_rig = rig if motion.skeleton.same_topology(rig.skeleton) else model_rig(motion.skeleton)
            data = mesh_rig.glb(motion)
        else:
            data = motion_bytes(motion, suffix)
        client.send_file_download(f"kinema_motion{suffix}", data, save_immediately=True)

    def _clip(self, name: str, content: bytes) -> None:
        """A BVH clip on the skeleton constraints are written for (the model's, or the rig's for a model for
        any rig or a character): joints matched by name."""
        skeleton, fps = self.host.skeleton, self.host.model.fps
        motion = clip_on_model(name, content, skeleton=skeleton, fps=fps, scale=UNITS[self.units.value])
        self.host.show_motions([motion], report=None, source=f"clip {name}")
        self.host.notify("Clip loaded", f"{name}: {motion.num_frames} frames")
