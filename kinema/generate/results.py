"""The list-like result of a ``generate`` call, shared by the human and the any-rig models."""

from __future__ import annotations

from collections.abc import Sequence

from kinema.motion.core import Motion


class MotionResults(Sequence):
    """The motions of one call (indexable like a list) and that call's own report (which must have
    ``seconds``); subclasses name the report type."""

    def __init__(self, motions: list[Motion], report) -> None:
        self.motions, self.report = list(motions), report

    def __getitem__(self, index):
        return self.motions[index]

    def __len__(self) -> int:
        return len(self.motions)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({len(self.motions)} motion(s), {self.report.seconds:.2f} s)"
