"""BVH reading: a raw layer (`parse_bvh` -> `BVHData`, file units and degrees, exactly as written)
and its conversion to a `Motion` (`read_bvh` / `bvh_data_to_motion`: metres, quaternions wxyz).
Writing lives in kinema.io.bvh_writer.

The raw layer accepts any per-joint channel layout (0-6 channels, any rotation order, position
channels on any joint), End Sites, CRLF/CR line ends, tabs, scientific notation and ``.gz`` files;
every error is a `BVHError` naming the file and, when it has one, the 1-based line.

This module is the public face; the work is split into kinema.io.bvh_data (the raw record and
limits), kinema.io.bvh_hierarchy (the HIERARCHY block), kinema.io.bvh_parse (input and the MOTION
block) and kinema.io.bvh_motion (conversion to `Motion`).
"""

from __future__ import annotations

from kinema.io.bvh_data import CHANNEL_NAMES, MAX_DEGREES, MAX_METRES, BVHData
from kinema.io.bvh_motion import bvh_data_to_motion, read_bvh
from kinema.io.bvh_parse import parse_bvh

__all__ = ["CHANNEL_NAMES", "MAX_DEGREES", "MAX_METRES", "BVHData", "bvh_data_to_motion", "parse_bvh", "read_bvh"]
