"""How far a generated motion lies from a recorded reference, in physical units.

Shared by tests/test_reference_outputs.py and scripts/measure_reference_spread.py (which measures the
CPU float noise the test's bounds are derived from). Joint positions and the root are compared in
millimetres, local rotations as the geodesic angle in degrees between the two quaternions (q and -q
are the same rotation, so a sign flip is no difference), foot contacts as the largest difference of
the contact probabilities.
"""

from __future__ import annotations

import numpy as np
import torch

from kinema.geometry.rotations import quat_angle_deg

FIELDS = ("root_mm", "pos_mm", "rot_deg", "contacts")


def motion_arrays(motion) -> dict[str, np.ndarray]:
    """The four recorded arrays of one generated motion (float32, as the fixture stores them)."""
    return {
        "root": motion.root_translation.float().numpy(),
        "pos": motion.positions.float().numpy(),
        "rot": motion.local_rotations.float().numpy(),
        "contacts": motion.foot_contacts.float().numpy(),
    }


def differences(got: dict[str, np.ndarray], want: dict[str, np.ndarray]) -> dict[str, float]:
    """Largest difference of each field between two motions' arrays (``motion_arrays`` layout)."""
    angle = quat_angle_deg(torch.from_numpy(got["rot"]).double(), torch.from_numpy(want["rot"]).double())
    return {
        "root_mm": 1000.0 * float(np.abs(got["root"].astype(np.float64) - want["root"]).max()),
        "pos_mm": 1000.0 * float(np.abs(got["pos"].astype(np.float64) - want["pos"]).max()),
        "rot_deg": float(angle.max()),
        "contacts": float(np.abs(got["contacts"].astype(np.float64) - want["contacts"]).max()),
    }


def recorded(reference: dict[str, np.ndarray], name: str, i: int) -> dict[str, np.ndarray]:
    """Sample ``i`` of case ``name`` from the fixture's flat ``{name}_{i}_{field}`` keys."""
    return {field: reference[f"{name}_{i}_{field}"] for field in ("root", "pos", "rot", "contacts")}


def sample_count(reference: dict[str, np.ndarray], name: str) -> int:
    return sum(1 for k in reference if k.startswith(f"{name}_") and k.endswith("_root"))
