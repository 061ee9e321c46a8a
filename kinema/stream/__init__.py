"""Live motion: an endless stream made window by window that follows prompt, steering and target
commands as they come (docs/stream.md). ``open_stream(model)`` -> `MotionStream`."""

from kinema.stream.continuation import CommandRecord, MotionStream, WindowStats, open_stream
from kinema.stream.frames import StreamFrames

__all__ = ["CommandRecord", "MotionStream", "StreamFrames", "WindowStats", "open_stream"]
