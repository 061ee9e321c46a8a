"""One browser tab: its document, motions, scene and panels. Generation runs on the app's worker pool
(never on viser's callback threads), with a progress bar fed by ``generate``'s step callback; results
and errors come back as scene updates and notifications. Tabs share the loaded model (``generate`` is thread-safe) and
nothing else."""

from __future__ import annotations

import threading
import traceback

import numpy as np

from kinema.app import generation as gen
from kinema.app.camera import CameraFollow, character_extent
from kinema.app.constraint_panel import ConstraintPanel
from kinema.app.document import Settings, added_prompt, check_timeline, default_document, load_document
from kinema.app.files_panel import FilesPanel
from kinema.app.live_panel import LivePanel
from kinema.app.markers import Markers, contact_flags_at
from kinema.app.mesh_view import MeshView, SkinPool
from kinema.app.page_script import PAGE_HTML
from kinema.app.playback import Player
from kinema.app.rig_panel import RigPanel
from kinema.app.rigs import AppRig, skeleton_size
from kinema.app.timeline_panel import TimelinePanel
from kinema.app.views import (
    OTHER_COLOR,
    ROBOT_COLOR,
    SELECTED_COLOR,
    CharacterView,
    SkeletonView,
    first_motions,
)
from kinema.errors import KinemaError

#: metres the character may move from the middle of the ground grid before the grid is moved under it
GROUND_RECENTRE = 4.0
#: spacing of the samples not selected (towards -X, away from the camera), drawn beside the selected one, in
#: sizes of the rig (its rest pose's largest extent: 1.6 m for the human model's 1.36 m)
SAMPLE_SPACING = 1.2
SAMPLE_NAMES = ("1", "2", "3", "4")
#: the share of the progress bar the denoiser steps fill; the rest is post-processing (foot contacts,
#: constraints, retargeting), which reports no steps
SAMPLING_SHARE = 90.0
#: warnings shown in the status and the notification (the rest are counted)
SHOWN_WARNINGS = 2
#: characters of one warning shown (a keyframe miss lists every joint: it is cut)
WARNING_CHARS = 160


class Session:
    def __init__(self, app, client):
        self.app, self.client, self.model, self.rig = app, client, app.model, app.rig
        #: the skeleton constraints are written for (the human model's own; any-rig: the starting rig)
        self.skeleton = self.constraint_skeleton(self.rig)
        self.doc = default_document(gen.is_any_rig(self.model), self.rig.name, Settings(steps=app.steps))
        self.motions = self.rig_motions()
        self.skin = self.rig.own_colors
        self.generated = False
        self.from_timeline = False  # the shown motion was generated from the timeline (not a clip)
        self.selected = 0
        self.job = None
        self.cancel = threading.Event()  # set by Cancel and when the tab closes: the job stops at its next step
        self.closed = False
        self.robot_motions: list = []
        self.lock = threading.Lock()
        scene, gui = client.scene, client.gui
        scene.set_up_direction("+y")
        self.ground = scene.add_grid(
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
        gui.add_html(PAGE_HTML)  # live keys and viser's upload notice (kinema.app.page_script)
        self.views: list[list[CharacterView]] = []
        self.skins = SkinPool(scene)
        self.markers = Markers(scene, self.skeleton, self.model.fps)
        self.timeline = TimelinePanel(
            gui,
            self.doc,
            self._length_changed,
            lambda t: self.notify(t, "", error=True),
            added_prompt(gen.is_any_rig(self.model), self.rig.name),
        )
        self._build_generate(gui)
        self.player = Player(gui, self.model.fps, self.show_frame)
        self.camera = CameraFollow(client, lambda: bool(self.player.follow.value))
        self.player.frame_btn.on_click(lambda _: self.frame_camera())
        self.constraints = ConstraintPanel(gui, scene, self)
        self.files = FilesPanel(gui, self)
        self.rig_panel = RigPanel(gui, self)
        self.live = LivePanel(gui, self)
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
            self.cancel_btn = gui.add_button(
                "Cancel", icon="x", color="red", visible=False, hint="stop this generation (nothing changes)"
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
        self.cancel_btn.on_click(lambda _: self.stop_job("Cancelled"))
        self.pick.on_click(lambda e: self.select_sample(SAMPLE_NAMES.index(e.target.value)))

    def notify(self, title: str, body: str, *, error: bool = False) -> None:
        if not self.closed:
            self.client.add_notification(title, body, color="red" if error else "blue", auto_close_seconds=8.0)

    # ------------------------------------------------------------------ motions
    def shown_motion(self):
        return self.motions[self.selected]

    def result_motion(self):
        """The shown motion once there is one (generated or uploaded), else None."""
        return self.shown_motion() if self.generated else None

    def show_motions(self, motions, *, report, source: str | None, robots=(), play: bool = False) -> None:
        """Replace the motions (samples) drawn, each with its robot motion when given; the first is
        selected, the camera frames it, and with ``play`` it plays from the start."""
        with self.lock:
            self.motions, self.generated, self.selected = list(motions), source is not None, 0
            self.from_timeline = source == "generated"
            self.robot_motions = list(robots)
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
        self.player.seek(0)
        self.frame_camera(keep_zoom=True)
        self.player.set_playing(play)

    def spacing(self) -> float:
        """Metres between samples side by side: scaled to the rig's size (twice that with a robot beside each)."""
        size = skeleton_size(self.shown_motion().skeleton)
        return SAMPLE_SPACING * size * (2.0 if self.robot_motions else 1.0)

    def lanes(self) -> list[float]:
        """X offset of each sample's lane, the selected one first (at 0)."""
        return [-k * self.spacing() for k in range(len(self.motions))]

    def select_sample(self, i: int) -> None:
        with self.lock:
            self.selected = min(max(i, 0), len(self.motions) - 1)
            others = [k for k in range(len(self.motions)) if k != self.selected]
            lanes = self.lanes()
            for k, group in enumerate(self.views):
                x = lanes[0 if k == self.selected else others.index(k) + 1]
                for view, motion in zip(group, self._group_motions(k), strict=True):
                    robot = motion is not self.motions[k]
                    view.color = ROBOT_COLOR if robot else SELECTED_COLOR if k == self.selected else OTHER_COLOR
                    view.trail = k == self.selected and not robot
                    view.remove()
                    shift = self.spacing() / 2 if robot else 0.0
                    view.set_motion(motion, offset=(x + shift, 0.0, 0.0))
        self.show_frame(self.player.frame)
        self.constraints.show_residuals()
        if len(self.motions) > 1:
            self.pick.label = f"Show sample ({self.selected + 1} in orange)"

    def _group_motions(self, k: int) -> list:
        """What each view of sample ``k`` draws: the sample (bones, skin), then its robot motion if any."""
        group = self.views[k]
        robot = self.robot_motions[k] if k < len(self.robot_motions) else None
        return [self.motions[k]] * (len(group) - (robot is not None)) + ([robot] if robot is not None else [])

    def show_frame(self, frame: int) -> None:
        with self.lock:
            for group in self.views:
                for view in group:
                    view.show(frame)
        # constraints are on this skeleton; the any-rig model takes no foot contacts (none drawn)
        shown = self.shown_motion()
        ours = shown.skeleton.same_topology(self.skeleton) and not gen.is_any_rig(self.model)
        flags = contact_flags_at(self.doc.constraints, frame) if ours else None
        self.markers.draw_contacts(shown, frame, flags)
        f = min(max(int(frame), 0), shown.num_frames - 1)
        root = shown.positions[f, 0].detach().double().numpy()
        self.camera.follow(root)
        self.ground_under(root)

    def ground_under(self, root: np.ndarray) -> None:
        """Keep the ground grid (24 m across) under the character, in playback as in live mode (a galloping
        fox ran off it into white space): moved by whole metres (its section size, so its lines stay put)
        once the character is `GROUND_RECENTRE` metres off its middle."""
        middle = np.asarray(self.ground.position, dtype=np.float64)
        if float(np.abs(root[[0, 2]] - middle[[0, 2]]).max()) > GROUND_RECENTRE:
            self.ground.position = (float(np.round(root[0])), 0.0, float(np.round(root[2])))

    def frame_camera(self, *, keep_zoom: bool = False) -> None:
        """Point the camera at the shown character (its widest pose, the samples beside it; the live one in
        live mode): a new motion (``keep_zoom``), the "Frame character" button and the F key."""
        run = self.live.run
        if run is not None and run.drawn >= 0:
            pose = np.asarray(run.view.positions[0], dtype=np.float64)
            run.camera.frame(pose, pose[0])
            return
        shown = self.shown_motion()
        positions = shown.positions.detach().double().numpy()
        frame = min(self.player.frame, len(positions) - 1)
        points = character_extent(positions, frame, self.lanes())
        if self.robot_motions:
            points = np.concatenate([points, points + np.array([self.spacing() / 2, 0.0, 0.0])])
        self.camera.frame(points, positions[frame, 0], keep_zoom=keep_zoom)

    def _length_changed(self) -> None:
        """The Frame slider and the constraints' frame range span the same frames: the timeline's (so that
        constraints can be laid out in time before generating; the rest pose, or the generated motion's
        last pose past its end, stands in), except for an uploaded clip or a rig's clip, shown whole."""
        frames = self.doc.num_frames(self.model.fps)
        clip = self.generated and not self.from_timeline
        self.player.set_length(self.shown_motion().num_frames if clip else frames)
        starts = self.doc.segment_starts(self.model.fps)
        self.player.set_segments([] if clip else [(f, s["prompt"]) for f, s in zip(starts, self.doc.timeline,
                                                                                    strict=True)])
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
            robot=self.app.robot,
        )
        self.cancel.clear()
        self.gen_btn.disabled, self.cancel_btn.visible = True, True
        self.progress.value, self.progress.visible = 0.0, True
        self.status.content = "Generating... (waiting for a free worker)"
        self.job = self.app.pool.submit(self._run, timeline, args)

    def stop_job(self, why: str) -> None:
        """Stop this tab's generation at its next denoiser step (Cancel, or the tab closing)."""
        job = self.job
        if job is None:
            return
        self.cancel.set()
        if job.cancel():  # still waiting in the pool's queue: it never starts
            self._job_done(f"{why}: nothing changed.")
        elif not self.closed:
            self.status.content = f"{why}: stopping at the next step..."

    def _run(self, timeline, args) -> None:
        done = "Failed (internal error, see the server log)."
        try:
            result = gen.outcome(self.model, self.rig, timeline, progress=self._progress, **args)
            if self.cancel.is_set():  # cancelled during post-processing: the result is dropped
                raise gen.Cancelled
            for note in result.notes:
                self.notify("Note", note)
            self.show_motions(result.motions, report=result, source="generated", robots=result.robot_motions, play=True)
            done = self._report(result)
        except gen.Cancelled:
            done = "Cancelled: nothing changed."
        except KinemaError as err:
            self.notify("Generation failed", _cut(str(err)), error=True)
            done = f"Failed: {_cut(str(err))}"
        except Exception as err:  # a bug: keep the page alive, log the traceback on the server
            traceback.print_exc()
            self.notify("Internal error", f"{type(err).__name__}: {_cut(str(err))}", error=True)
        finally:
            self._job_done(done)

    def _job_done(self, status: str) -> None:
        self.job = None
        if self.closed:
            return
        self.status.content = status
        self.gen_btn.disabled, self.cancel_btn.visible = False, False
        self.progress.visible = False

    def _progress(self, done: int, total: int) -> None:
        """The denoiser steps done so far (``generate``'s progress callback, on the worker thread); raises
        `Cancelled` once Cancel was pressed or the tab closed, which stops the pipeline there."""
        if self.cancel.is_set():
            raise gen.Cancelled
        self.progress.value = SAMPLING_SHARE * done / total
        if done < total:
            self.status.content = f"Generating... step {done} of {total}"
        else:
            self.status.content = (
                f"Post-processing (foot contacts, constraints{', retargeting' if self._retargets() else ''})... "
                f"all {total} steps done"
            )

    def _retargets(self) -> bool:
        return gen.is_character(self.model, self.rig) or self.app.robot is not None

    def _report(self, report: gen.Outcome) -> str:
        """The status text after a generation; its warnings (unmet constraints, prompts the model does not
        know) in a short list and one notification."""
        lines, toast = summarize_warnings(report.warnings)
        if toast:
            self.notify("Generated, with warnings", toast, error=True)
        return report.text + ("\n\n" + "\n".join(lines) if lines else "")

    # ------------------------------------------------------------------ rigs
    def constraint_skeleton(self, rig: AppRig):
        """The skeleton constraints are written for: the rig's when the model generates on it (any-rig
        model) or retargets onto it (a character for the human model), else the model's own."""
        on_rig = gen.is_any_rig(self.model) or gen.is_character(self.model, rig)
        return rig.skeleton if on_rig else self.model.skeleton

    def rig_motions(self) -> list:
        """What a rig shows before anything is generated: its first clip, else its rest pose."""
        return first_motions(self.rig, self.model.fps)

    def _views(self, i: int, skeleton) -> list[CharacterView]:
        """Sample ``i``'s views: the skin when shown, else the bones; planted contacts and the trail always;
        then the robot's body frames when a robot is shown."""
        color = SELECTED_COLOR if i == 0 else OTHER_COLOR
        scene, rig = self.client.scene, self.rig
        contacts = rig.contacts if skeleton.same_topology(rig.skeleton) else None
        skin = self.skin and skeleton.same_topology(rig.skeleton)
        views: list[CharacterView] = [
            SkeletonView(scene, f"/sample{i}", skeleton, color=color, contacts=contacts, bones=not skin)
        ]
        if skin:
            views.append(MeshView(self.skins, i, skeleton, rig.mesh, color=color, own_colors=rig.own_colors))
        if i < len(self.robot_motions):
            views.append(SkeletonView(scene, f"/robot{i}", self.robot_motions[i].skeleton, color=ROBOT_COLOR))
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
        skeleton = self.constraint_skeleton(rig)
        if not skeleton.same_topology(self.skeleton):
            self._constraints_on(skeleton)
        self.rig_panel.refresh()
        self.show_motions(self.rig_motions(), report=None, source=f"rig {rig.name}")
        self._say_if_playback_only()

    def _constraints_on(self, skeleton) -> None:
        """A rig with other joints: constraints are now written for ``skeleton`` (the old ones, made for
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
        elif gen.is_character(self.model, self.rig):
            self.notify(
                f"{self.rig.name}: humanoid character",
                "motions are generated on the model's skeleton and retargeted onto it",
            )

    def show_clip(self, name: str) -> None:
        self.rig_panel.select(name)
        self.show_motions([self.rig.clips[name]], report=None, source=f"clip {name} of {self.rig.name}")

    # ------------------------------------------------------------------ files
    def load_session(self, name: str, content: bytes) -> None:
        """Load a session file whole, or refuse it whole (a one-line message; nothing changes)."""
        if self.job is not None:
            raise KinemaError(f"{name}: not loaded while generating (press Cancel first)")
        doc = load_document(
            content, skeleton=self.skeleton, fps=self.model.fps, source=name, max_steps=gen.max_steps(self.model)
        )
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
        """The tab closed: its generation stops at the next step, its clock stops."""
        self.closed = True
        self.live.close()
        self.stop_job("Tab closed")
        self.player.close()


def summarize_warnings(warnings: list[str]) -> tuple[list[str], str]:
    """(status lines, notification text) for a generation's warnings: the first ``SHOWN_WARNINGS``, each
    cut to one line of ``WARNING_CHARS``, and how many more there are; ([], "") without warnings."""
    distinct = list(dict.fromkeys(warnings))
    if not distinct:
        return [], ""
    shown = [_cut(w) for w in distinct[:SHOWN_WARNINGS]]
    more = f" (+{len(distinct) - SHOWN_WARNINGS} more)" if len(distinct) > SHOWN_WARNINGS else ""
    return [f"- {w}" for w in shown[:-1]] + [f"- {shown[-1]}{more}"], f"{shown[0]}{more}"


def _cut(text: str, chars: int = WARNING_CHARS) -> str:
    """The first line of ``text``, at most ``chars`` characters."""
    text = text.strip()
    line = text.splitlines()[0] if text else ""
    if len(line) > chars:
        return line[: chars - 1].rstrip() + "…"
    return line if line == text else line + " …"
