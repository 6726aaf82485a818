"""Random bone flaps on the skull: seeded, reachable, convex loops of landmarks for sweeps.

A flap is drawn in four steps, each from one seeded generator:

1. The skull, locally: a sphere about the isocenter whose radius is drawn uniformly between
   the smallest and the largest distance of the base problem's landmarks from the
   isocenter (67.8–72.2 mm for the paper's A1–A4), so that a flap lies where the paper's
   skull does.
2. The shape: ``landmarks`` points around the flap's centre, counterclockwise seen from
   outside the skull, at even azimuths each shifted by up to ±25 % of the spacing, and at
   angular distances from the centre of 85–100 % of a common one. That common distance is
   then solved for so that the flap's size, the largest distance between two landmarks, is
   the size drawn uniformly in ``size_range_mm``.
3. The centre: uniform on the cap of the robot's workspace, the directions within the angle
   α of the direction at the middle of the joint range, α the largest angle of a reachable
   direction from it (within the joint range and the singularity margin: 67.8° about the
   vertex for the prototype, whose ±60° box is what binds). Centres further out than α less
   the flap's inradius are not drawn: the joint-range box is bounded by great circles
   (θ1 or θ2 constant), so a flap within it lies within α of the axis, contour and all.
4. The checks: positions rounded to 0.01 mm as in the problem files, the loop convex (on
   the tangent plane at the centre, where great-circle arcs are straight), a valid
   :class:`~spm_opt.problem.Problem` with the base problem's robot, and its contour within
   the workspace between the landmarks too. A draw that fails any of them is redrawn with
   the same size, at most :data:`MAX_ATTEMPTS` times.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import brentq

from spm_opt.contour import Contour
from spm_opt.errors import InputError, UnreachableError
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.problem import Problem

MIN_SIZE_MM = 1.0
"""Smallest flap size, mm: smaller is no flap, and rounding to 0.01 mm would distort it."""
MAX_ATTEMPTS = 1000
"""Draws of one flap (of one size) before the size is declared impossible."""
AZIMUTH_JITTER = 0.25
"""Largest shift of a landmark's azimuth about the centre, as a fraction of the spacing."""
RADIAL_JITTER = 0.15
"""Largest shortening of a landmark's angular distance from the centre (a fraction)."""
_GRID = 41
"""Joint angles per axis of the grid that finds the workspace's extent."""
_CONTOUR_SAMPLES = 16
"""Contour points checked per segment."""
_CHECK_SPEED_MM_S = 1.0
"""Tool speed, mm/s, of the durations of the problem built to check a draw (durations do
not change reachability; at 1 mm/s every segment on a skull takes less than an hour)."""


@dataclass(frozen=True, eq=False)
class Flap:
    """A closed loop of landmarks on the skull (compare flaps by their ``positions_mm``).

    Attributes
    ----------
    names : tuple of str
        ``"F1"``, ``"F2"``, … in visiting order.
    positions_mm : ndarray, shape (n, 3), mm
        The landmarks, rounded to 0.01 mm.
    size_mm : float, mm
        The largest distance between two landmarks, as drawn (the rounded positions match
        it to 0.02 mm).
    """

    names: tuple[str, ...]
    positions_mm: np.ndarray
    size_mm: float

    def landmark_overrides(self) -> list[dict[str, Any]]:
        """The landmarks as a problem file's ``[[landmarks]]`` tables (plain floats, mm)."""
        return [
            {"name": name, "position_mm": [float(value) for value in position]}
            for name, position in zip(self.names, self.positions_mm, strict=True)
        ]

    def segment_durations_s(self, speed_mm_s: float) -> list[float]:
        """Duration of each segment of the closed loop, s, at a nominal tool speed.

        Parameters
        ----------
        speed_mm_s : float, mm/s
            The segment's length along the contour (great-circle arc, skull radius
            interpolated) divided by it, rounded up to 0.1 s, at least 1 s.
        """
        if not (_is_number(speed_mm_s) and math.isfinite(speed_mm_s) and speed_mm_s > 0):
            raise InputError(f"speed_mm_s = {speed_mm_s!r}: expected a positive number (mm/s)")
        lengths_mm = Contour(self.positions_mm * MM, closed=True).arc_lengths / MM
        return [
            max(1.0, math.ceil(round(length / speed_mm_s * 10, 6)) / 10) for length in lengths_mm
        ]

    def problem(self, base: Problem, speed_mm_s: float) -> Problem:
        """The base problem (robot, limits, options) cutting this flap at ``speed_mm_s``.

        Raises
        ------
        UnreachableError
            If a landmark is out of the base robot's reach.
        """
        return dataclasses.replace(
            base,
            name=f"{base.name}_flap",
            description=f"A random {len(self.names)}-landmark bone flap of {self.size_mm:.2f} mm",
            landmark_names=self.names,
            landmarks=self.positions_mm * MM,
            closed=True,
            segment_durations=np.array(self.segment_durations_s(speed_mm_s)),
            source=None,
            source_sha256=None,
        )


@dataclass(frozen=True)
class _Workspace:
    frame: np.ndarray  # columns: two tangent directions and the axis (unit)
    half_angle: float  # rad
    radii: tuple[float, float]  # skull radii, m


def random_flaps(
    problem: Problem,
    count: int,
    size_range_mm: tuple[float, float],
    landmarks: int = 4,
    seed: int = 0,
) -> list[Flap]:
    """Random bone flaps within the reach of ``problem.robot`` (see the module's docstring).

    Parameters
    ----------
    problem : Problem
        The base problem: its robot and the radii of its landmarks.
    count : int
        Number of flaps, at least 1.
    size_range_mm : (float, float), mm
        The range of the flaps' sizes (largest distance between two landmarks), drawn
        uniformly; ``MIN_SIZE_MM <= low <= high``.
    landmarks : int
        Landmarks per flap, at least 3.
    seed : int
        Seed of the generator: the same arguments give the same flaps.

    Raises
    ------
    InputError
        On a bad argument, or when a drawn size cannot be placed in the workspace.
    """
    _check_arguments(count, size_range_mm, landmarks, seed)
    low, high = (float(value) for value in size_range_mm)
    workspace = _workspace(problem)
    rng = np.random.default_rng(seed)
    flaps = []
    for _ in range(count):
        size_mm = float(rng.uniform(low, high))
        for _ in range(MAX_ATTEMPTS):
            flap = _draw(problem, workspace, rng, size_mm, landmarks)
            if flap is not None:
                flaps.append(flap)
                break
        else:
            largest = 2 * workspace.radii[1] * math.sin(workspace.half_angle) / MM
            raise InputError(
                f"size_range_mm = ({low:g}, {high:g}): no {landmarks}-landmark flap of "
                f"{size_mm:.1f} mm fits the workspace of robot {problem.robot.name!r} in "
                f"{MAX_ATTEMPTS} draws (within {math.degrees(workspace.half_angle):.1f}° of "
                f"its axis on a skull of up to {workspace.radii[1] / MM:.1f} mm, no two "
                f"reachable points are more than {largest:.0f} mm apart)"
            )
    return flaps


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _check_arguments(count: Any, size_range_mm: Any, landmarks: Any, seed: Any) -> None:
    def integer(value: Any) -> bool:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)

    if not integer(count) or count < 1:
        raise InputError(f"count = {count!r}: expected an integer of at least 1")
    if not integer(landmarks) or landmarks < 3:
        raise InputError(f"landmarks = {landmarks!r}: expected an integer of at least 3")
    if not integer(seed) or seed < 0:
        raise InputError(f"seed = {seed!r}: expected a non-negative integer")
    try:
        low, high = size_range_mm
    except (TypeError, ValueError):
        low = high = math.nan
    if not (
        _is_number(low)
        and _is_number(high)
        and math.isfinite(low)
        and math.isfinite(high)
        and MIN_SIZE_MM <= low <= high
    ):
        raise InputError(
            f"size_range_mm = {size_range_mm!r}: expected (low, high) in mm with "
            f"{MIN_SIZE_MM:g} <= low <= high, both finite"
        )


def _frame(axis: np.ndarray) -> np.ndarray:
    """A right-handed orthonormal frame (3, 3) whose third column is the unit ``axis``."""
    helper = np.eye(3)[np.argmin(np.abs(axis))]
    first = helper - (helper @ axis) * axis
    first /= np.linalg.norm(first)
    return np.column_stack([first, np.cross(axis, first), axis])


def _workspace(problem: Problem) -> _Workspace:
    """The cap of directions the robot reaches and the skull radii of the base problem."""
    robot = problem.robot
    middle = robot.joint_range.mean(axis=1)
    axis = kinematics.forward_kinematics(middle[None, :], 1.0)[0]
    theta1, theta2 = (np.linspace(low, high, _GRID) for low, high in robot.joint_range)
    q = np.stack(np.meshgrid(theta1, theta2, indexing="ij"), axis=-1).reshape(-1, 2)
    reachable = [reason is None for reason in robot.unreachable_reason(q)]
    directions = kinematics.forward_kinematics(q[reachable], 1.0)
    half_angle = float(np.max(np.arccos(np.clip(directions @ axis, -1.0, 1.0))))
    radii = np.linalg.norm(problem.landmarks, axis=1)
    return _Workspace(_frame(axis), half_angle, (float(radii.min()), float(radii.max())))


def _diameter(points: np.ndarray) -> float:
    """Largest distance between two of the points (n, 3)."""
    return float(np.max(np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)))


def _draw(
    problem: Problem, workspace: _Workspace, rng: np.random.Generator, size_mm: float, n: int
) -> Flap | None:
    """One draw of a flap of ``size_mm``, or None if it fails a check."""
    radius = rng.uniform(*workspace.radii)
    spacing = 2 * math.pi / n
    azimuth = spacing * (np.arange(n) + rng.uniform(-AZIMUTH_JITTER, AZIMUTH_JITTER, n))
    azimuth += rng.uniform(0.0, 2 * math.pi)
    reach = rng.uniform(1.0 - RADIAL_JITTER, 1.0, n)

    def shape(polar: float) -> np.ndarray:
        """Unit directions (n, 3) about the centre z for a common angular distance, rad."""
        angle = polar * reach
        return np.column_stack(
            [np.sin(angle) * np.cos(azimuth), np.sin(angle) * np.sin(azimuth), np.cos(angle)]
        )

    def excess(polar: float) -> float:
        return radius * _diameter(shape(polar)) / MM - size_mm

    largest_polar = workspace.half_angle / reach.max()
    if excess(largest_polar) < 0.0:
        return None
    local = shape(brentq(excess, 0.0, largest_polar, xtol=1e-12))
    edge_normals = np.cross(local, np.roll(local, -1, axis=0))
    edge_normals /= np.linalg.norm(edge_normals, axis=1, keepdims=True)
    inradius = float(np.arcsin(np.min(np.abs(edge_normals[:, 2]))))
    cap = workspace.half_angle - inradius
    tilt = math.acos(rng.uniform(math.cos(cap), 1.0))
    turn = rng.uniform(0.0, 2 * math.pi)
    centre = workspace.frame @ [
        math.sin(tilt) * math.cos(turn),
        math.sin(tilt) * math.sin(turn),
        math.cos(tilt),
    ]
    frame = _frame(centre)
    positions_mm = np.round(radius / MM * local @ frame.T, 2) + 0.0  # + 0.0: no -0.0
    if not _convex(positions_mm @ frame):
        return None
    flap = Flap(tuple(f"F{i + 1}" for i in range(n)), positions_mm, size_mm)
    try:
        candidate = flap.problem(problem, _CHECK_SPEED_MM_S)
        s = np.linspace(0.0, candidate.contour.length, _CONTOUR_SAMPLES * n)
        reasons = problem.robot.unreachable_reason(candidate.contour_angles(s))
    except UnreachableError:
        return None
    return flap if all(reason is None for reason in reasons) else None


def _convex(local: np.ndarray) -> bool:
    """Whether points (n, 3), in a frame whose z is the flap's centre, turn left at every
    landmark on the tangent plane there (gnomonic projection: great circles are lines)."""
    plane = local[:, :2] / local[:, 2:]
    edges = np.roll(plane, -1, axis=0) - plane
    following = np.roll(edges, -1, axis=0)
    return bool(np.all(edges[:, 0] * following[:, 1] - edges[:, 1] * following[:, 0] > 0.0))
