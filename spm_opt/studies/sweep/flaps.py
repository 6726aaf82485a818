"""Random bone flaps on the skull: seeded, reachable, convex loops of landmarks for sweeps.

A flap's shape is drawn in four steps, all from one generator seeded by ``seed``:

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
   :class:`~spm_opt.problem.problem.Problem` with the base problem's robot, and its contour within
   the workspace between the landmarks too. A draw that fails any of them is redrawn with
   the same size, at most :data:`MAX_ATTEMPTS` times.

Three more values may be drawn per flap, each from a stream of its own (children of the
same seed, :meth:`numpy.random.SeedSequence.spawn`), so that asking for one changes
neither the shapes nor the other draws, and the same arguments give the same flaps:

- the landmark count, uniform on the integers of ``landmarks = (low, high)`` (inclusive;
  an integer ``landmarks`` draws nothing, and ``(4, 4)`` gives the flaps of ``4``);
- the contour tolerance, mm, **log-uniform** in ``contour_tolerance_mm = (low, high)``:
  every factor of the range is equally likely (as many tubes of 0.05–0.1 mm as of
  0.1–0.2 mm), since halving a tube is as much harder at 0.1 mm as at 0.2 mm; uniform
  draws would put two thirds of the flaps above 0.1 mm and leave the tight tubes, where
  planners fail, the least sampled;
- the tool-speed limit, mm/s, uniform in ``max_tool_speed_mm_s = (low, high)``.

A drawn limit replaces the base problem's (:meth:`Flap.problem`, :meth:`Flap.limit_overrides`),
and the segment durations then keep a mean tool speed of at most
:data:`DURATION_SPEED_FRACTION` of the drawn tool-speed limit (:meth:`Flap.mean_speed_mm_s`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import brentq

from spm_opt.base.errors import InputError, UnreachableError
from spm_opt.base.input_limits import excerpt
from spm_opt.cut.contour import segment_durations_s
from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem

MIN_SIZE_MM = 1.0
"""Smallest flap size, mm: smaller is no flap, and rounding to 0.01 mm would distort it."""
MAX_ATTEMPTS = 1000
"""Draws of one flap (of one size) before the size is declared impossible."""
AZIMUTH_JITTER = 0.25
"""Largest shift of a landmark's azimuth about the centre, as a fraction of the spacing."""
RADIAL_JITTER = 0.15
"""Largest shortening of a landmark's angular distance from the centre (a fraction)."""
DURATION_SPEED_FRACTION = 2 / 3
"""Largest mean tool speed of a flap's segment durations, as a fraction of its drawn
tool-speed limit: the fixed-time planners need slack over the limit's lower bound on the
durations, and this is the paper problem's (2 mm/s of a 3 mm/s limit), at which a cubic
that starts and ends a segment at rest peaks at the limit (its peak is 3/2 its mean)."""
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
    contour_tolerance_mm : float or None, mm
        The drawn contour tolerance; None: the base problem's.
    max_tool_speed_mm_s : float or None, mm/s
        The drawn tool-speed limit; None: the base problem's.
    """

    names: tuple[str, ...]
    positions_mm: np.ndarray
    size_mm: float
    contour_tolerance_mm: float | None = None
    max_tool_speed_mm_s: float | None = None

    def landmark_overrides(self) -> list[dict[str, Any]]:
        """The landmarks as a problem file's ``[[landmarks]]`` tables (plain floats, mm)."""
        return [
            {"name": name, "position_mm": [float(value) for value in position]}
            for name, position in zip(self.names, self.positions_mm, strict=True)
        ]

    def limit_overrides(self) -> dict[str, float]:
        """The drawn limits as problem-file overrides, the drawn ones only:
        ``limits.contour_tolerance_mm`` (mm) and ``limits.max_tool_speed_mm_s`` (mm/s)."""
        drawn = {
            "limits.contour_tolerance_mm": self.contour_tolerance_mm,
            "limits.max_tool_speed_mm_s": self.max_tool_speed_mm_s,
        }
        return {key: value for key, value in drawn.items() if value is not None}

    def mean_speed_mm_s(self, tool_speed_mm_s: float) -> float:
        """The mean tool speed, mm/s, to set the segment durations by: ``tool_speed_mm_s``
        (mm/s), but at most :data:`DURATION_SPEED_FRACTION` of the drawn tool-speed limit."""
        if self.max_tool_speed_mm_s is None:
            return tool_speed_mm_s
        return min(tool_speed_mm_s, DURATION_SPEED_FRACTION * self.max_tool_speed_mm_s)

    def segment_durations_s(self, speed_mm_s: float) -> list[float]:
        """Duration of each segment of the closed loop, s, at a nominal tool speed.

        Parameters
        ----------
        speed_mm_s : float, mm/s
            The segment's length along the contour (great-circle arc, skull radius
            interpolated) divided by it, rounded up to 0.1 s, at least 1 s.
        """
        if not (_is_number(speed_mm_s) and math.isfinite(speed_mm_s) and speed_mm_s > 0):
            raise InputError(
                f"speed_mm_s = {excerpt(speed_mm_s)}: expected a positive number (mm/s)"
            )
        return segment_durations_s(self.positions_mm * MM, True, speed_mm_s)

    def problem(self, base: Problem, speed_mm_s: float) -> Problem:
        """The base problem (robot, limits, options) cutting this flap, with its drawn limits,
        in segment durations of mean tool speed :meth:`mean_speed_mm_s` of ``speed_mm_s``
        (mm/s).

        Raises
        ------
        UnreachableError
            If a landmark is out of the base robot's reach.
        """
        drawn = {
            "contour_tolerance": self.contour_tolerance_mm,
            "max_tool_speed": self.max_tool_speed_mm_s,
        }
        limits = {name: value * MM for name, value in drawn.items() if value is not None}
        return dataclasses.replace(
            base,
            name=f"{base.name}_flap",
            description=f"A random {len(self.names)}-landmark bone flap of {self.size_mm:.2f} mm",
            landmark_names=self.names,
            landmarks=self.positions_mm * MM,
            closed=True,
            segment_durations=np.array(self.segment_durations_s(self.mean_speed_mm_s(speed_mm_s))),
            limits=dataclasses.replace(base.limits, **limits),
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
    landmarks: int | tuple[int, int] = 4,
    seed: int = 0,
    *,
    contour_tolerance_mm: tuple[float, float] | None = None,
    max_tool_speed_mm_s: tuple[float, float] | None = None,
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
    landmarks : int or (int, int)
        Landmarks per flap, at least 3; or the inclusive range each flap's count is drawn
        from, uniformly (``3 <= low <= high``).
    seed : int
        Seed of the generator: the same arguments give the same flaps.
    contour_tolerance_mm : (float, float), mm, optional
        The range each flap's contour tolerance is drawn from, log-uniformly
        (``0 < low <= high``); by default the flaps keep the base problem's.
    max_tool_speed_mm_s : (float, float), mm/s, optional
        The range each flap's tool-speed limit is drawn from, uniformly
        (``0 < low <= high``); by default the flaps keep the base problem's.

    Raises
    ------
    InputError
        On a bad argument, or when a drawn size cannot be placed in the workspace.
    """
    _check_arguments(count, size_range_mm, landmarks, seed)
    _check_limit_ranges(contour_tolerance_mm, max_tool_speed_mm_s)
    low, high = (float(value) for value in size_range_mm)
    fewest, most = (landmarks, landmarks) if _is_integer(landmarks) else landmarks
    workspace = _workspace(problem)
    rng = np.random.default_rng(seed)
    counts, tolerances, speeds = (
        np.random.default_rng(child) for child in np.random.SeedSequence(seed).spawn(3)
    )
    flaps = []
    for _ in range(count):
        size_mm = float(rng.uniform(low, high))
        n = int(counts.integers(fewest, most + 1))
        flap = _place(problem, workspace, rng, size_mm, n, (low, high))
        flaps.append(
            dataclasses.replace(
                flap,
                contour_tolerance_mm=_log_uniform(tolerances, contour_tolerance_mm),
                max_tool_speed_mm_s=_uniform(speeds, max_tool_speed_mm_s),
            )
        )
    return flaps


def _place(
    problem: Problem,
    workspace: _Workspace,
    rng: np.random.Generator,
    size_mm: float,
    n: int,
    size_range_mm: tuple[float, float],
) -> Flap:
    """A flap of ``size_mm`` with ``n`` landmarks, drawn until one passes the checks."""
    for _ in range(MAX_ATTEMPTS):
        flap = _draw(problem, workspace, rng, size_mm, n)
        if flap is not None:
            return flap
    largest = 2 * workspace.radii[1] * math.sin(workspace.half_angle) / MM
    low, high = size_range_mm
    raise InputError(
        f"size_range_mm = ({low:g}, {high:g}): no {n}-landmark flap of "
        f"{size_mm:.1f} mm fits the workspace of robot {problem.robot.name!r} in "
        f"{MAX_ATTEMPTS} draws (within {math.degrees(workspace.half_angle):.1f}° of "
        f"its axis on a skull of up to {workspace.radii[1] / MM:.1f} mm, no two "
        f"reachable points are more than {largest:.0f} mm apart)"
    )


def _uniform(rng: np.random.Generator, bounds: tuple[float, float] | None) -> float | None:
    """A value uniform in ``bounds`` (low, high), or None (drawing nothing) without them."""
    return None if bounds is None else float(rng.uniform(*bounds))


def _log_uniform(rng: np.random.Generator, bounds: tuple[float, float] | None) -> float | None:
    """A value whose logarithm is uniform in ``bounds`` (0 < low <= high; low itself when
    they are equal), or None (drawing nothing) without them."""
    if bounds is None:
        return None
    low, high = (float(value) for value in bounds)
    return low * (high / low) ** float(rng.uniform())


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _is_integer(value: Any) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _check_arguments(count: Any, size_range_mm: Any, landmarks: Any, seed: Any) -> None:
    if not _is_integer(count) or count < 1:
        raise InputError(f"count = {excerpt(count)}: expected an integer of at least 1")
    if not (_is_integer(landmarks) and landmarks >= 3 or _is_landmark_range(landmarks)):
        raise InputError(
            f"landmarks = {excerpt(landmarks)}: expected an integer of at least 3, or (low, high) "
            "integers with 3 <= low <= high"
        )
    if not _is_integer(seed) or seed < 0:
        raise InputError(f"seed = {excerpt(seed)}: expected a non-negative integer")
    _check_range("size_range_mm", size_range_mm, "mm", MIN_SIZE_MM, exclusive=False)


def _check_limit_ranges(contour_tolerance_mm: Any, max_tool_speed_mm_s: Any) -> None:
    """Raise unless each range given is (low, high) with 0 < low <= high, both finite."""
    for name, bounds, unit in (
        ("contour_tolerance_mm", contour_tolerance_mm, "mm"),
        ("max_tool_speed_mm_s", max_tool_speed_mm_s, "mm/s"),
    ):
        if bounds is not None:
            _check_range(name, bounds, unit, 0.0, exclusive=True)


def _is_landmark_range(value: Any) -> bool:
    """Whether ``value`` is a (low, high) pair of integers with 3 <= low <= high."""
    return (
        isinstance(value, tuple | list)
        and len(value) == 2
        and all(_is_integer(item) for item in value)
        and 3 <= value[0] <= value[1]
    )


def _check_range(name: str, bounds: Any, unit: str, minimum: float, exclusive: bool) -> None:
    """Raise unless ``bounds`` is (low, high), both finite, ``low <= high`` and ``low``
    above ``minimum`` (or equal to it, unless ``exclusive``)."""
    try:
        low, high = bounds
    except (TypeError, ValueError):
        low = high = math.nan
    finite = all(_is_number(value) and math.isfinite(value) for value in (low, high))
    if not (finite and (low > minimum or low == minimum and not exclusive) and low <= high):
        floor = f"{minimum:g} {'<' if exclusive else '<='}"
        raise InputError(
            f"{name} = {excerpt(bounds)}: expected (low, high) in {unit} with {floor} low <= high, "
            "both finite"
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
