"""What the planners and the evaluator ask of the skull: its radius in a direction.

The tool's axis is the ray from the isocenter along the platform's unit direction p; the
tool cuts where that ray meets the skull's outer surface, at the radius ρ(p). Two surfaces
answer: a mesh from imaging (:class:`spm_opt.skull.raycast.MeshSurface`, ray casts) and,
without one, a smooth surface through the landmarks
(:class:`spm_opt.skull.landmark_surface.LandmarkSurface`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    import trimesh


class SkullSurface(Protocol):
    """The skull's outer surface seen from the isocenter, in the robot's frame."""

    def radius(self, directions: np.ndarray) -> np.ndarray:
        """Distance (N,), m, from the isocenter to the outer surface along unit directions
        (N, 3)."""
        ...

    def radius_gradient(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The radius (N,), m, and its gradient on the unit sphere (N, 3), m/rad, tangent
        to the sphere: ρ̇ = gradient · ṗ for a direction moving at ṗ."""
        ...


@dataclass(frozen=True)
class Skull:
    """The skull a problem plans on.

    Attributes
    ----------
    surface : SkullSurface
        Its outer surface's radius in every direction (a mesh's ray casts, or the smooth
        surface through the landmarks).
    outer_mesh, inner_mesh : trimesh.Trimesh or None
        The outer and inner surfaces in the robot's frame, m, when the problem names them.
    registration_rms_mm : float or None
        The fiducial registration error (RMS of the fiducials' residuals), mm, when the
        image-to-robot transform came from fiducials.
    fiducial_residuals_mm : ndarray (n,) or None
        Each fiducial's residual, mm: how far the fit puts it from where the robot
        located it.
    landmark_shifts_mm : ndarray (n,) or None
        How far each landmark moved along its direction onto the outer mesh, mm.
    fingerprint : str
        SHA-256 (hex) of what a plan depends on: the meshes in the robot's frame.
    depth_margin : float, m
        The tool tip's depth setpoint lies this far outside the inner surface.
    image_to_robot_mm : ndarray (4, 4) or None
        The registration: the image's RAS coordinates, mm, to the robot's frame, mm (None
        when the problem gives none).
    """

    surface: SkullSurface
    outer_mesh: trimesh.Trimesh | None = None
    inner_mesh: trimesh.Trimesh | None = None
    registration_rms_mm: float | None = None
    fiducial_residuals_mm: np.ndarray | None = None
    landmark_shifts_mm: np.ndarray | None = None
    fingerprint: str = ""
    depth_margin: float = 0.0
    image_to_robot_mm: np.ndarray | None = None
