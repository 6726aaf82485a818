"""The two frames of medical imaging: RAS (+x right, +y anterior, +z superior, as 3D Slicer
shows) and LPS (+x left, +y posterior, +z superior, as DICOM and Slicer's files use).

Both are in the patient's millimetres; one turns into the other by negating x and y.
"""

from __future__ import annotations

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt

FRAMES = ("RAS", "LPS")
"""The frames a mesh or a markups file may be in, spelt in upper case."""

_SIGNS = {"RAS": np.array([1.0, 1.0, 1.0]), "LPS": np.array([-1.0, -1.0, 1.0])}


def check_frame(value: object, field: str) -> str:
    """``value`` if it names a frame of :data:`FRAMES` (upper case only), else InputError
    naming ``field``."""
    if not isinstance(value, str) or value not in FRAMES:
        raise InputError(
            f"{field} = {excerpt(value)}: expected 'RAS' or 'LPS' (the meshes' frame, in "
            "upper case)"
        )
    return value


def to_ras(points_mm: np.ndarray, frame: str) -> np.ndarray:
    """Points (n, 3), mm, given in ``frame``, in RAS (a new array; mm).

    The map is its own inverse: it also takes RAS points to ``frame``.
    """
    return np.asarray(points_mm, dtype=float) * _SIGNS[check_frame(frame, "frame")]


def frame_matrix(frame: str) -> np.ndarray:
    """The homogeneous matrix (4, 4) from ``frame`` to RAS (its own inverse)."""
    matrix = np.eye(4)
    matrix[:3, :3] = np.diag(_SIGNS[check_frame(frame, "frame")])
    return matrix
