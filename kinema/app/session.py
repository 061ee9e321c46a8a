"""One browser tab: its document, motions, scene and panels. Generation runs on the app's worker pool
(never on viser's callback threads), with a progress bar fed by ``generate``'s step callback; results
and errors come back as scene updates and notifications. Tabs share the loaded model (``generate`` is thread-safe) and
nothing else."""

from __future__ import annotations

import threading
import traceback

from kinema.app import generation as gen
from kinema.app.constraint_panel import ConstraintPanel
from kinema.app.document import Document, Settings, check_timeline, load_document
from kinema.app.files_panel import FilesPanel
from kinema.app.markers import Markers, contact_flags_at
from kinema.app.mesh_view import MeshView, SkinPool
from kinema.app.playback import Player
from kinema.app.rig_panel import RigPanel
from kinema.app.rigs import AppRig
from kinema.app.timeline_panel import TimelinePanel
from kinema.app.views import OTHER_COLOR, SELECTED_COLOR, CharacterView, SkeletonView, rest_motion
from kinema.errors import KinemaError

#: spacing (metres, towards -X, away from the camera) of the samples not selected, drawn beside the selected one
SAMPLE_SPACING = 1.6
SAMPLE_NAMES = ("1", "2", "3", "4")


class Session:
    def __init__(self, app, client):
        self.app, self.client, self.model, self.rig = app, client, app.model, app.rig
        #: the skeleton constraints are written for (the human model's own; any-rig: the starting rig)
        self.skeleton = self.rig.skeleton if gen.is_any_rig(self.model) else self.model.skeleton
        self.doc = Document(settings=Settings(steps=app.steps))
        self.motions = self.rig_motions()
        self.skin = self.rig.own_colors
        self.generated = False
        self.selected = 0
        self.job = None
        self.lock = threading.Lock()
        scene, gui = client.scene, client.gui
        scene.set_up_direction("+y")
        scene.add_grid(
            "/ground",
            width=24,
            height=24,
            plane="xz",
            cell_size=0.5,
            section_size=1.0,
            plane_color=(235, 235, 240),
            plane_opacity=0.6,
        )
        gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        gui.main_panel.dock_right()
        self.views: list[list[CharacterView]] = []
        self.skins = SkinPool(scene)
        self.markers = Markers(scene, self.skeleton, self.model.fps)
        self.timeline = TimelinePanel(gui, self.doc, self._length_changed, lambda t: self.notify(t, "", error=True))
        self._build_generate(gui)
        self.player = Player(gui, self.model.fps, self.show_frame)
        self.constraints = ConstraintPanel(gui, scene, self)
        self.files = FilesPanel(gui, self)
        self.rig_panel = RigPanel(gui, self)
        self.show_motions(self.motions, report=None, source=f"rig {self.rig.name}" if self.rig.clips else None)
        self._length_changed()
        self._say_if_playback_only()

    # ------------------------------------------------------------------ panels
    def _build_generate(self, gui) -> None:
        s = self.doc.settings
        with gui.add_folder("Generate"):
            self.gen_btn = gui.add_button(
                "Generate",
                icon="wand",
                color="green",
                hint="generate from the timeline, keeping the constraints",
            )
            self.progress = gui.add_progress_bar(0.0, visible=False, animated=True)
            self.status = gui.add_markdown("Write prompts in the timeline, then press **Generate**.")
            self.samples = gui.add_slider("Samples", min=1, max=4, step=1, initial_value=s.samples)
            self.seed = gui.add_number("Seed", s.seed, min=0, step=1)
            self.steps = gui.add_number(
                "Steps",
                s.steps or gen.default_steps(self.model),
                min=1,
                max=gen.max_steps(self.model),
                step=1,
                hint="DDIM steps: fewer is faster",
            )
            self.pick = gui.add_button_group("Show sample", SAMPLE_NAMES[:1])
        self.gen_btn.on_click(lambda _: self.generate())
        self.pick.on_click(lambda e: self.select_sample(SAMPLE_NAMES.index(e.target.value)))

    def notify(self, title: str, body: str, *, error: bool = False) -> None:
        self.client.add_notification(title, body, color="red" if error else "blue", auto_close_seconds=8.0)

    # ------------------------------------------------------------------ motions
    def shown_motion(self):
        return self.motions[self.selected]

    def result_motion(self):
        """The shown motion once there is one (generated or uploaded), else None."""
        return self.shown_motion() if self.generated else None

    def show_motions(self, motions, *, report, source: str | None) -> None:
        """Replace the motions (samples) drawn; the first is selected."""
        with self.lock:
            self.motions, self.generated, self.selected = list(motions), source is not None, 0
            for group in self.views:
                for v in group:
                    v.remove()
            self.views = [self._views(i, m.skeleton) for i, m in enumerate(self.motions)]
        self.pick.options = SAMPLE_NAMES[: len(motions)]
        self.pick.visible = len(motions) > 1
        self.select_sample(0)
        if source is not None and report is None:
            self.status.content = f"Showing {source}."
        self._length_changed()

    def select_sample(self, i: int) -> None:
        with self.lock:
            self.selected = min(max(i, 0), len(self.motions) - 1)
            others = [k for k in range(len(self.motions)) if k != self.selected]
            for k, group in enumerate(self.views):
                lane = 0 if k == self.selected else others.index(k) + 1
                for view in group:
                    view.color = SELECTED_COLOR if k == self.selected else OTHER_COLOR
                    view.trail = k == self.selected
                    view.remove()
                    view.set_motion(self.motions[k], offset=(-lane * SAMPLE_SPACING, 0.0, 0.0))
        self.show_frame(self.player.frame)
        self.constraints.show_residuals()
        if len(self.motions) > 1:
            self.pick.label = f"Show sample ({self.selected + 1} in orange)"

    def show_frame(self, frame: int) -> None:
        with self.lock:
            for group in self.views:
                for view in group:
                    view.show(frame)
        # constraints are on this skeleton; the any-rig model takes no foot contacts (none drawn)
        ours = self.shown_motion().skeleton.same_topology(self.skeleton) and not gen.is_any_rig(self.model)
        flags = contact_flags_at(self.doc.constraints, frame) if ours else None
        self.markers.draw_contacts(self.shown_motion(), frame, flags)

    def _length_changed(self) -> None:
        """The slider spans the shown motion, or the timeline before anything is generated (so that
        constraints can be laid out in time first; the rest pose stands in for every frame)."""
        frames = self.doc.num_frames(self.model.fps)
        self.player.set_length(self.shown_motion().num_frames if self.generated else frames)
        self.constraints.set_length(frames)

    # ------------------------------------------------------------------ generation
    def generate(self) -> None:
        if self.job is not None:
            self.notify("Busy", "this tab is already generating", error=True)
            return
        try:
            timeline = check_timeline(self.doc.timeline)
            self.doc.settings = Settings(
                samples=int(self.samples.value), seed=int(self.seed.value), steps=int(self.steps.value)
            )
        except (KinemaError, ValueError) as err:
            self.notify("Cannot generate", str(err), error=True)
            return
        why = gen.cannot_generate(self.model, self.rig, self.app.model_name)
        if why is not None:
            self.notify("Cannot generate for this rig", why, error=True)
            self.status.content = f"Cannot generate: {why}"
            return
        args = dict(
            constraints=[dict(c) for c in self.doc.constraints] or None,
            samples=self.doc.settings.samples,
            steps=self.doc.settings.steps,
            seed=self.doc.settings.seed,
        )
        self.gen_btn.disabled = True
        self.progress.value, self.progress.visible = 0.0, True
        self.status.content = "Generating..."
        self.job = self.app.pool.submit(self._run, timeline, args)

    def _run(self, timeline, args) -> None:
        try:
            result = gen.outcome(self.model, self.rig, timeline, progress=self._progress, **args)
            for note in result.notes:
                self.notify("Note", note)
            self.show_motions(result.motions, report=result, source="generated")
            self._report(result)
        except KinemaError as err:
            self.notify("Generation failed", str(err), error=True)
            self.status.content = f"Failed: {err}"
        except Exception as err:  # a bug: keep the page alive, log the traceback on the server
            traceback.print_exc()
            self.notify("Internal error", f"{type(err).__name__}: {err}", error=True)
            self.status.content = "Failed (internal error, see the server log)."
        finally:
            self.job = None
            self.gen_btn.disabled = False
            self.progress.visible = False

    def _progress(self, done: int, total: int) -> None:
        """The denoiser steps done so far (``generate``'s progress callback, on the worker thread)."""
        self.progress.value = 100.0 * done / total
        self.status.content = f"Generating... step {done} of {total}"

    def _report(self, report: gen.Outcome) -> None:
        text = report.text
        if report.warnings:
            text += "\n\n" + "\n".join(f"- {w}" for w in dict.fromkeys(report.warnings))
            self.notify("Constraints not all met", "; ".join(dict.fromkeys(report.warnings)), error=True)
        self.status.content = text

    # ------------------------------------------------------------------ rigs
    def rig_motions(self) -> list:
        """What a rig shows before anything is generated: its first clip, else its rest pose."""
        return list(self.rig.clips.values())[:1] or [rest_motion(self.rig.skeleton, self.model.fps)]

    def _views(self, i: int, skeleton) -> list[CharacterView]:
        """Sample ``i``'s views: the skin when shown, else the bones; planted contacts and the trail always."""
        color = SELECTED_COLOR if i == 0 else OTHER_COLOR
        scene, rig = self.client.scene, self.rig
        contacts = rig.contacts if skeleton.same_topology(rig.skeleton) else None
        skin = self.skin and skeleton.same_topology(rig.skeleton)
        views: list[CharacterView] = [
            SkeletonView(scene, f"/sample{i}", skeleton, color=color, contacts=contacts, bones=not skin)
        ]
        if skin:
            views.append(MeshView(self.skins, i, skeleton, rig.mesh, color=color, own_colors=rig.own_colors))
        return views

    def redraw(self) -> None:
        """Rebuild the views of the motions shown (after the skin was switched on or off)."""
        with self.lock:
            for group in self.views:
                for v in group:
                    v.remove()
            self.views = [self._views(i, m.skeleton) for i, m in enumerate(self.motions)]
        self.select_sample(self.selected)

    def set_rig(self, rig: AppRig) -> None:
        """Show ``rig`` (and its first clip); say when the model cannot generate for it."""
        self.rig = rig
        self.skin = rig.own_colors
        if gen.is_any_rig(self.model) and not rig.skeleton.same_topology(self.skeleton):
            self._constraints_on(rig.skeleton)
        self.rig_panel.refresh()
        self.show_motions(self.rig_motions(), report=None, source=f"rig {rig.name}")
        self._say_if_playback_only()

    def _constraints_on(self, skeleton) -> None:
        """Any-rig model, new rig: constraints are now written for ``skeleton`` (the old ones, made for
        another skeleton, are cleared and the joint list is the new rig's)."""
        dropped = len(self.doc.constraints)
        self.skeleton = skeleton
        self.doc.constraints.clear()
        self.constraints.refresh(select=None)  # the old markers go
        self.markers = Markers(self.client.scene, skeleton, self.model.fps)
        self.constraints.set_skeleton(skeleton)
        if dropped:
            self.notify("Constraints cleared", f"{dropped} constraint(s) were made for the previous rig")

    def _say_if_playback_only(self) -> None:
        why = gen.cannot_generate(self.model, self.rig, self.app.model_name)
        if why is not None:
            self.notify(f"{self.rig.name}: playback only", why, error=True)

    def show_clip(self, name: str) -> None:
        self.rig_panel.select(name)
        self.show_motions([self.rig.clips[name]], report=None, source=f"clip {name} of {self.rig.name}")

    # ------------------------------------------------------------------ files
    def load_session(self, name: str, content: bytes) -> None:
        doc = load_document(content, skeleton=self.skeleton, fps=self.model.fps, source=name)
        self.doc = doc
        self.timeline.set_document(doc)
        s = doc.settings
        self.samples.value, self.seed.value = s.samples, s.seed
        if s.steps is not None:
            self.steps.value = s.steps
        self._length_changed()
        self.constraints.refresh(select=None)
        self.notify("Session loaded", f"{name}: {len(doc.timeline)} prompt(s), {len(doc.constraints)} constraint(s)")

    def close(self) -> None:
        self.player.close()
