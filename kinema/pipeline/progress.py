"""Generation progress for callers that draw their own bar (the app): ``generate(..., progress=fn)``.

``fn(done, total)`` is called from the generating thread after every denoiser step that moves the
count, with ``total`` the denoiser steps of the whole call (a timeline: ``steps`` per segment plus the
shorter passes of its join windows) and ``done`` increasing up to ``total``. A pass sampled in several
batch chunks (many samples) advances in proportion to its chunks' steps.
"""

from __future__ import annotations

from collections.abc import Callable

from kinema.errors import KinemaError

ProgressFn = Callable[[int, int], None]


class StepProgress:
    """Maps each sampling pass's own ``(done, total)`` step counts onto one count for the whole call;
    ``steps[k]`` is the number of denoiser steps of pass ``k``."""

    def __init__(self, callback: ProgressFn, *, steps: list[int]):
        self.callback, self.steps, self.total, self.done = callback, list(steps), sum(steps), 0

    def segment(self, k: int) -> ProgressFn:
        """The ``on_step`` callback for pass ``k`` (0-based)."""
        offset, steps = sum(self.steps[:k]), self.steps[k]

        def on_step(done: int, total: int) -> None:
            value = offset + done * steps // total
            if value > self.done:
                self.done = value
                self.callback(value, self.total)

        return on_step


def split_progress(progress) -> tuple[bool, ProgressFn | None]:
    """``progress`` (False, True for a tqdm bar, or a callable) -> (tqdm bar?, callback or None)."""
    if isinstance(progress, bool):
        return progress, None
    if callable(progress):
        return False, progress
    raise KinemaError(f"progress must be True, False or a callable(done, total), got {progress!r}")
