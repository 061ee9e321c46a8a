"""The raw BVH record (`BVHData`: file units, Euler angles in degrees, channels as listed) and the
limits the reader enforces; shared by the parser (kinema.io.bvh_parse), the conversion to `Motion`
(kinema.io.bvh_motion) and the writer (kinema.io.bvh_writer)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Channel names as written in files; matching is case-insensitive.
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
#: Largest rotation channel value read (degrees): beyond it the angle has lost all precision (a
#: corrupt file), though unwrapped angles of many turns are fine.
MAX_DEGREES = 1e7
#: Largest length read, in metres after ``scale``: beyond it a value is corrupt (or the scale wrong),
#: and it would not fit the float32 arrays of kinema's npz format either.
MAX_METRES = 1e6


@dataclass(eq=False)
class BVHData:
    """A BVH file exactly as written: file units, Euler angles in degrees, channels as listed.

    ``values[:, c]`` is channel ``c`` counted across joints in hierarchy order (the order of
    ``names``); `column_starts` gives where each joint's channels begin.
    """

    names: list[str]
    parents: list[int]
    offsets: np.ndarray  # (J, 3) float64, file units
    channels: list[list[str]]  # per joint, canonical names in file order
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)  # joint -> (3,) End Site offset
    frame_time: float = 1.0 / 30.0
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (T, C) float64
    path: str = ""

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    @property
    def column_starts(self) -> list[int]:
        """Index into ``values`` of each joint's first channel."""
        starts, c = [], 0
        for chans in self.channels:
            starts.append(c)
            c += len(chans)
        return starts
