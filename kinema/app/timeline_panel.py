"""The timeline panel: prompts with their durations (add, remove, reorder, edit).

Rows are rebuilt after every structural change (the list is short); typing only updates the document.
Durations are seconds, at least ``MIN_SECONDS``; the total may exceed the model's window (long
segments are split and joined by the generator, kinema.pipeline.timeline).
"""

from __future__ import annotations

from collections.abc import Callable

from kinema.app.document import MAX_SEGMENT_SECONDS, MIN_SEGMENT_SECONDS, Document

MIN_SECONDS = MIN_SEGMENT_SECONDS
MAX_SECONDS = MAX_SEGMENT_SECONDS
ROW_ACTIONS = ("▲", "▼", "✕")


def clamp_seconds(value) -> float:
    """A typed duration brought into [MIN_SECONDS, MAX_SECONDS] (text that is not a number: MIN_SECONDS)."""
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        return MIN_SECONDS
    return min(max(seconds, MIN_SECONDS), MAX_SECONDS) if seconds == seconds else MIN_SECONDS


class TimelinePanel:
    """GUI for ``doc.timeline``; ``changed()`` is called after each edit (to refresh frame ranges)."""

    def __init__(
        self,
        gui,
        doc: Document,
        changed: Callable[[], None],
        notify: Callable[[str], None],
        new_prompt: str = "A person stands still.",
    ):
        self.gui, self.doc, self.changed, self.notify, self.new_prompt = gui, doc, changed, notify, new_prompt
        with gui.add_folder("Timeline"):
            self.rows_box = gui.add_folder(None)
            self.add_btn = gui.add_button("Add prompt", icon="plus", hint="append a prompt to the timeline")
            self.total = gui.add_markdown("")
        self.add_btn.on_click(lambda _: self._add())
        self.handles: list = []
        self.rebuild()

    def set_document(self, doc: Document) -> None:
        self.doc = doc
        self.rebuild()

    def rebuild(self) -> None:
        for h in self.handles:
            h.remove()
        self.handles = []
        with self.rows_box:
            for i, seg in enumerate(self.doc.timeline):
                self._row(i, seg)
        self._total()

    def _row(self, i: int, seg: dict) -> None:
        text = self.gui.add_text(f"Prompt {i + 1}", seg["prompt"], hint="what happens in this segment")
        secs = self.gui.add_number(
            f"Seconds {i + 1}",
            float(seg["seconds"]),
            min=MIN_SECONDS,
            max=MAX_SECONDS,
            step=0.5,
            hint="duration of this segment",
        )
        acts = self.gui.add_button_group(f"Segment {i + 1}", ROW_ACTIONS, hint="move up, move down, remove")
        self.handles += [text, secs, acts]

        @text.on_update
        def _(_) -> None:
            seg["prompt"] = text.value

        @secs.on_update
        def _(_) -> None:
            seg["seconds"] = clamp_seconds(secs.value)
            if secs.value != seg["seconds"]:  # out-of-range text does not stay in the box
                secs.value = seg["seconds"]
            self._total()
            self.changed()

        @acts.on_click
        def _(event) -> None:
            self._act(i, event.target.value)

    def _act(self, i: int, action: str) -> None:
        tl = self.doc.timeline
        if action == "✕":
            if len(tl) == 1:
                self.notify("The timeline needs at least one prompt.")
                return
            del tl[i]
        elif action == "▲" and i > 0:
            tl[i - 1], tl[i] = tl[i], tl[i - 1]
        elif action == "▼" and i + 1 < len(tl):
            tl[i + 1], tl[i] = tl[i], tl[i + 1]
        else:
            return
        self.rebuild()
        self.changed()

    def _add(self) -> None:
        self.doc.timeline.append({"prompt": self.new_prompt, "seconds": 3.0})
        self.rebuild()
        self.changed()

    def _total(self) -> None:
        self.total.content = f"Total **{self.doc.seconds():.1f} s** in {len(self.doc.timeline)} segment(s)"
