"""The constraints panel: tools that add constraints from the scene and a list to select, move,
retime and delete them.

- Click the ground (mode "waypoint") to lay a waypoint at the shown frame; mode "path" collects points
  until "Finish path" makes one dense path over the chosen frame range.
- "Keyframe pose" keeps the shown pose at the shown frame; "Add target" pins a joint where it is
  now (position and/or rotation) and gives it a gizmo to drag.
- "Add contacts" plants or lifts the feet over a frame range.
The selected constraint carries the transform gizmo (drag it to move the constraint). ``host`` is the
tab's Session: it supplies the shown motion and frame, the document, notifications and redraws.
"""

from __future__ import annotations

import math
import re

from kinema.app import edits
from kinema.app import generation as gen
from kinema.app.residuals import residual
from kinema.app.rig_constraints import waypoint_residual
from kinema.app.rigs import skeleton_size
from kinema.errors import KinemaError

CLICK_MODES = ("off", "waypoint", "path")
#: the move gizmo's size in sizes of the rig (0.45 m for a person: reachable, not hiding the character)
GIZMO_SIZE = 0.27
#: joint names of helper bones (IK targets, poles, roots of controls): never the default joint to pin
HELPER_BONE = re.compile(r"(^|[^a-z])(ik|pole|target|ctrl|control)|^(ff|ffb)[._]|root$|armature$", re.IGNORECASE)
TARGET_MODES = {"position": (True, False), "rotation": (False, True), "position + rotation": (True, True)}


class ConstraintPanel:
    def __init__(self, gui, scene, host):
        self.gui, self.scene, self.host = gui, scene, host
        self.path_points: list[tuple[float, float]] = []
        self.gizmo = None
        with gui.add_folder("Constraints"):
            self.mode = gui.add_dropdown(
                "Click ground", CLICK_MODES, initial_value="waypoint", hint="what a click on the ground adds"
            )
            self.heading = gui.add_checkbox(
                "Headings", False, hint="waypoints face the way the gizmo turns; paths face along the path"
            )
            self.finish_path = gui.add_button(
                "Finish path",
                disabled=True,
                hint="turn the clicked points into a dense path over the frame range below",
            )
            self.keyframe_btn = gui.add_button(
                "Keyframe pose", icon="camera", hint="keep the whole pose shown at this frame"
            )
            self.joint = gui.add_dropdown("Joint", ("(none)",), initial_value="(none)")
            self.set_skeleton(host.skeleton)
            self.target_mode = gui.add_dropdown("Target", tuple(TARGET_MODES), initial_value="position")
            self.target_btn = gui.add_button(
                "Add target", icon="target", hint="pin the joint where it is at this frame; drag the gizmo to move it"
            )
            self._build_contacts(gui)
            self.items = gui.add_dropdown("Selected", ("(none)",), initial_value="(none)")
            self.heading_deg = gui.add_slider(
                "Heading (deg)",
                min=-180,
                max=180,
                step=5,
                initial_value=0,
                visible=False,
                hint="facing of the selected waypoint (0 = +Z)",
            )
            row = gui.add_button_group("Edit", ("to this frame", "to range", "delete", "clear all"))
            self.residual_md = gui.add_markdown("")
        self.mode.on_update(lambda _: self._mode_changed())
        self.finish_path.on_click(lambda _: self._safely(self._finish_path))
        self.keyframe_btn.on_click(lambda _: self._safely(self._keyframe))
        self.target_btn.on_click(lambda _: self._safely(self._target))
        self.contact_btn.on_click(lambda _: self._safely(self._contacts))
        self.items.on_update(lambda _: self._select_changed())
        self.range.on_update(lambda _: self._range_to_boxes())
        self.range_from.on_update(lambda _: self._boxes_to_range())
        self.range_to.on_update(lambda _: self._boxes_to_range())
        self.heading_deg.on_update(lambda _: self._heading_changed())
        row.on_click(lambda e: self._safely(lambda: self._edit(e.target.value)))
        scene.on_click()(self._clicked)

    def _build_contacts(self, gui) -> None:
        """Feet, the Frames range with its From / To boxes, and Add contacts."""
        self.contact = gui.add_dropdown(
            "Feet",
            tuple(edits.CONTACT_PRESETS),
            initial_value=next(iter(edits.CONTACT_PRESETS)),
            hint="each choice sets both feet over the range: a foot not planted is held off the ground",
        )
        self.range = gui.add_multi_slider(
            "Frames", min=0, max=1, step=1, initial_value=(0, 1), hint="frame range for contacts and paths"
        )
        self.range_from = gui.add_number("From frame", 0, min=0, max=1, step=1, hint="first frame of the range")
        self.range_to = gui.add_number("To frame", 1, min=0, max=1, step=1, hint="last frame of the range")
        self.contact_btn = gui.add_button(
            "Add contacts", icon="shoe", hint="plant / lift the feet over the frame range"
        )

    # ------------------------------------------------------------------ helpers
    @property
    def constraints(self) -> list[dict]:
        return self.host.doc.constraints

    def _safely(self, fn) -> None:
        try:
            fn()
        except KinemaError as err:
            self.host.notify("Cannot do that", str(err), error=True)

    def _add(self, c: dict) -> None:
        self.constraints.append(c)
        self.refresh(select=len(self.constraints) - 1)

    def selected_index(self) -> int | None:
        """The selected constraint, by the number its label starts with (a waypoint's label changes with
        the speed it asks for when another one moves)."""
        number = str(self.items.value).split(".", 1)[0]
        return int(number) - 1 if number.isdigit() and 0 < int(number) <= len(self.constraints) else None

    def _labels(self) -> list[str]:
        """Each constraint's list label; a waypoint's says the ground speed it asks for, before generating."""
        fps = self.host.model.fps
        speeds = edits.waypoint_speeds(self.constraints, fps)
        return [f"{i + 1}. {edits.label(c, fps)}" + (f" asks {speeds[i]:.1f} m/s, {edits.speed_words(speeds[i])}"
                                                    if i in speeds else "") for i, c in enumerate(self.constraints)]

    def set_length(self, num_frames: int) -> None:
        """Frame ranges follow the timeline's length; a range that reached the old end keeps reaching it."""
        hi = max(1, num_frames - 1)
        lo_v, hi_v = self.range.value
        old_end = self.range.max
        self.range.max = hi
        lo_v = min(lo_v, hi - 1)
        self.range.value = (lo_v, hi if hi_v >= old_end or hi_v > hi or hi_v <= lo_v else hi_v)
        self.range_from.max = self.range_to.max = hi
        self._range_to_boxes()

    def _range_to_boxes(self) -> None:
        lo, hi = (int(v) for v in self.range.value)
        if (self.range_from.value, self.range_to.value) != (lo, hi):
            self.range_from.value, self.range_to.value = lo, hi

    def _boxes_to_range(self) -> None:
        """Typed frames set the range exactly (kept inside the timeline, in order); the boxes show what was set."""
        lo, hi = edits.frame_range(self.range_from.value, self.range_to.value, int(self.range.max))
        if tuple(int(v) for v in self.range.value) != (lo, hi):
            self.range.value = (lo, hi)
        self._range_to_boxes()

    # ------------------------------------------------------------------ list
    def refresh(self, select: int | None = None) -> None:
        """Rebuild the list, markers, gizmo and residuals after any change."""
        labels = self._labels()
        keep = self.selected_index() if select is None else select
        self.items.options = tuple(labels) or ("(none)",)
        self.items.value = labels[keep] if keep is not None and keep < len(labels) else self.items.options[0]
        self._select_changed()

    def _select_changed(self) -> None:
        i = self.selected_index()
        self.host.markers.draw(self.constraints, i)
        self._place_gizmo(i)
        c = None if i is None else self.constraints[i]
        is_wp = c is not None and c["type"] == "root2d" and not c.get("dense")
        self.heading_deg.visible = is_wp and "global_root_heading" in c
        if self.heading_deg.visible:
            cs, sn = c["global_root_heading"][0]
            self.heading_deg.value = int(round(math.degrees(math.atan2(sn, cs)) / 5) * 5)
        self.show_residuals()

    def show_residuals(self) -> None:
        motion = self.host.result_motion()
        if motion is None or not self.constraints:
            self.residual_md.content = "" if self.constraints else "No constraints yet."
            return
        lines = [
            f"- {lab}: {self._residual(c, motion)}" for lab, c in zip(self._labels(), self.constraints, strict=True)
        ]
        self.residual_md.content = "**Residuals** (shown motion)\n" + "\n".join(lines)

    def _residual(self, c: dict, motion) -> str:
        """Measured in the world as for the human model; the any-rig model takes no rotations or foot
        contacts (kinema.app.rig_constraints), which is said instead."""
        if not gen.is_any_rig(self.host.model) or c["type"] == "fullbody":
            return residual(c, motion)
        if c["type"] == "root2d":
            return waypoint_residual(c, motion)
        if c["type"] == "foot-contact" or "positions" not in c:
            return "not used by this model"
        return residual({k: v for k, v in c.items() if k != "rotations"}, motion) + (
            ", rotation not used" if "rotations" in c else ""
        )

    def set_skeleton(self, skeleton) -> None:
        """The joints targets can pin: those of the skeleton constraints are written for."""
        names = tuple(skeleton.names)
        self.joint.options = names
        self.joint.value = _default_joint(skeleton)

    def _place_gizmo(self, i: int | None) -> None:
        if self.gizmo is not None:
            self.gizmo.remove()
            self.gizmo = None
        if i is None or self.constraints[i]["type"] == "foot-contact":
            return
        c = self.constraints[i]
        ground = c["type"] in ("root2d", "fullbody")
        rotates = c["type"] == "end-effector" and "rotations" in c
        self.gizmo = self.scene.add_transform_controls(
            "/gizmo",
            scale=GIZMO_SIZE * skeleton_size(self.host.skeleton),
            position=edits.anchor(c),
            wxyz=edits.rotation_wxyz(c),
            active_axes=(True, not ground, True),
            disable_rotations=not rotates,
            depth_test=False,
        )

        @self.gizmo.on_update
        def _(event) -> None:
            j = self.selected_index()
            if j is None or event.phase != "end":
                return
            self.constraints[j] = edits.moved(self.constraints[j], self.gizmo.position, self.gizmo.wxyz)
            self.refresh(select=j)

    def _heading_changed(self) -> None:
        i = self.selected_index()
        if i is None or "global_root_heading" not in self.constraints[i]:
            return
        self.constraints[i]["global_root_heading"] = [edits.heading_vector(math.radians(self.heading_deg.value))]
        self.host.markers.draw(self.constraints, i)

    def _edit(self, action: str) -> None:
        i = self.selected_index()
        if action == "clear all":
            self.constraints.clear()
            self.path_points = []
        elif i is None:
            raise KinemaError("select a constraint first")
        elif action == "delete":
            del self.constraints[i]
            i = min(i, len(self.constraints) - 1) if self.constraints else None
        elif action == "to range":
            self.constraints[i] = edits.spanned(self.constraints[i], *self.range.value)
        else:
            self.constraints[i] = edits.retimed(self.constraints[i], self.host.player.frame)
        self.refresh(select=i)

    # ------------------------------------------------------------------ tools
    def _mode_changed(self) -> None:
        self.path_points = []
        self.finish_path.disabled = True

    def _clicked(self, event) -> None:
        hit = edits.ground_point(event.ray_origin, event.ray_direction)
        if hit is None or self.mode.value == "off":
            return
        if self.host.live.running:  # the timeline's motion is hidden: a click would edit what is not shown
            self.host.notify("Nothing added in live mode",
                             "steer with the arrow keys or the Live buttons; ground clicks add waypoints to the "
                             "timeline's motion after Stop live", error=True)
            return
        if self.mode.value == "waypoint":
            frame = self.host.player.frame
            if any(c["type"] == "root2d" and frame in c["frame_indices"] for c in self.constraints):
                self.host.notify(
                    "Waypoint not added",
                    f"frame {frame} already has a waypoint: scrub to another frame first",
                    error=True,
                )
                return
            self._add(edits.waypoint(frame, *hit, heading=0.0 if self.heading.value else None))
            speed = edits.waypoint_speeds(self.constraints, self.host.model.fps)[len(self.constraints) - 1]
            if edits.speed_words(speed) == edits.TOO_FAST:
                self.host.notify("A very fast waypoint", f"it asks for {speed:.1f} m/s, {edits.TOO_FAST}; "
                                 "scrub to a later frame or click nearer", error=True)
        else:
            self.path_points.append(hit)
            self.finish_path.disabled = len(self.path_points) < 2
            self.host.markers.draw_pending(self.path_points)

    def _finish_path(self) -> None:
        lo, hi = self.range.value
        self._add(edits.path(self.path_points, lo, hi, headings=self.heading.value))
        self.path_points = []
        self.finish_path.disabled = True
        self.host.markers.draw_pending([])

    def _keyframe(self) -> None:
        self._add(edits.keyframe(self.host.shown_motion(), self.host.player.frame))

    def _target(self) -> None:
        pos, rot = TARGET_MODES[self.target_mode.value]
        self._add(
            edits.target(self.host.shown_motion(), self.host.player.frame, self.joint.value, position=pos, rotation=rot)
        )

    def _contacts(self) -> None:
        lo, hi = self.range.value
        self._add(edits.contacts(lo, hi, self.contact.value))


def _default_joint(skeleton) -> str:
    """The joint "Add target" starts with: the right hand, else the head, else the last joint that is no
    helper bone (Quaternius rigs end with IK targets such as ``IKFrontLeg.R``)."""
    for role in ("right_hand", "head"):
        j = skeleton.roles.get(role)
        if j is not None:
            return skeleton.names[j]
    names = [n for n in skeleton.names if not HELPER_BONE.search(n)]
    return (names or list(skeleton.names))[-1]
