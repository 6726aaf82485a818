"""Which error angles a set of poses can identify, and how well: the identification
Jacobian's rank, its base set by QR and its observability indices.

The Jacobian's columns are scaled to metres at the marker (an angle's column by the
marker's distance), so singular values compare like with like. The registration and the
marker's distance are always estimated: the error angles are projected onto what they
leave unexplained, and a QR factorisation with column pivoting of that projection
(as FIGAROH's ``BaseCalibration`` reduces its parameters) ranks the angles; those whose
pivot falls below :data:`RANK_TOLERANCE` of the largest are not identifiable from these
poses and stay at their prior value.

The indices (Sun and Hollerbach, ICRA 2008), for the singular values σ of the scaled
Jacobian of the estimated unknowns, L of them, over m poses:
O1 = (σ1…σL)^(1/L)/√m (Menq and Borm; D-optimal), O2 = σL/σ1 (Driels and Pathre; the
inverse condition number), O3 = σL (Nahvi et al.; E-optimal), O4 = σL²/σ1 (Nahvi and
Hollerbach's noise amplification index).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from spm_opt.calibration.measurement import GEOMETRY_START, UNKNOWNS

RANK_TOLERANCE = 1e-6
"""Pivot of an error angle's projected column, relative to the largest, below which the
angle is not identifiable."""


@dataclass(frozen=True)
class Observability:
    """How well the estimated unknowns are seen (:attr:`estimated` indexes UNKNOWNS).

    Attributes
    ----------
    estimated : tuple of int
        The unknowns the fit estimates: the registration, the marker's distance and the
        identifiable error angles.
    unidentified : tuple of str
        The error angles these poses cannot separate from the others.
    singular_values : ndarray, m
    o1, o2, o3, o4 : float
        The indices of the module's docstring (O1, O3 in m; O2 dimensionless; O4 in m).
    """

    estimated: tuple[int, ...]
    unidentified: tuple[str, ...]
    singular_values: np.ndarray
    o1: float
    o2: float
    o3: float
    o4: float

    @property
    def condition_number(self) -> float:
        """σ1/σL (1/O2): below about 100 is the usual rule for a reliable fit."""
        return 1.0 / self.o2

    def to_dict(self) -> dict[str, object]:
        """Plain data for reports."""
        return {
            "estimated": [UNKNOWNS[i] for i in self.estimated],
            "unidentified": list(self.unidentified),
            "o1_m": self.o1,
            "o2": self.o2,
            "o3_m": self.o3,
            "o4_m": self.o4,
            "condition_number": self.condition_number,
        }


def column_scales(marker_distance_m: float) -> np.ndarray:
    """Each unknown's column scale to metres at the marker: the Cayley vector's and the
    angles' by the marker's distance (twice for the Cayley vector, half an angle), the
    translation's and the distance's by 1."""
    scales = np.ones(len(UNKNOWNS))
    scales[:3] = 2.0 * marker_distance_m
    scales[GEOMETRY_START:] = marker_distance_m
    return scales


def observability(jacobian: np.ndarray, marker_distance_m: float, poses: int) -> Observability:
    """The base set and the indices of an identification Jacobian (3m, len(UNKNOWNS))."""
    scaled = jacobian / column_scales(marker_distance_m)
    always = list(range(GEOMETRY_START))
    q, _ = np.linalg.qr(scaled[:, always])
    angles = scaled[:, GEOMETRY_START:]
    residual = angles - q @ (q.T @ angles)
    _, r, pivots = scipy.linalg.qr(residual, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(r))
    kept = diagonal > RANK_TOLERANCE * max(float(diagonal[0]), 1e-300)
    identified = sorted(GEOMETRY_START + int(p) for p in pivots[kept])
    unidentified = tuple(UNKNOWNS[GEOMETRY_START + int(p)] for p in sorted(pivots[~kept].tolist()))
    estimated = tuple(always + identified)
    sigma = np.linalg.svd(scaled[:, estimated], compute_uv=False)
    o1 = float(np.exp(np.mean(np.log(sigma))) / np.sqrt(poses))
    return Observability(
        estimated=estimated,
        unidentified=unidentified,
        singular_values=sigma,
        o1=o1,
        o2=float(sigma[-1] / sigma[0]),
        o3=float(sigma[-1]),
        o4=float(sigma[-1] ** 2 / sigma[0]),
    )
