"""A planning problem: the robot, the landmarks to cut through, timing and limits.

Problems live in TOML files (``problems/*.toml``) with the unit in every key; they are
converted to SI once, here. A :class:`Problem` checks itself when built, from a file or from
code, so that every planner receives a problem the robot can carry out.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.errors import InputError, UnreachableError
from spm_opt.base.fields import Table, apply_overrides, read_toml
from spm_opt.base.files import json_default
from spm_opt.base.input_limits import MAX_LANDMARKS, excerpt
from spm_opt.cut.contour import Contour
from spm_opt.model import kinematics
from spm_opt.model.actuator import RPM
from spm_opt.model.params import MM, Robot, load_robot
from spm_opt.skull.arc_fit import ArcRadiusFit, fit_arc_radius
from spm_opt.skull.landmark_surface import LandmarkSurface
from spm_opt.skull.problem_keys import markup_landmarks, read_skull_table, skull_on_mesh
from spm_opt.skull.smooth_radius import SmoothRadius
from spm_opt.skull.surface import Skull, SkullSurface

SAMPLES_PER_SEGMENT = 2001
"""Contour points per segment at which the duration's lower bound integrates the pace."""

_LOG = logging.getLogger(__name__)
_SAME_DIRECTION_RAD = 1e-6
MIN_SEGMENT_DURATION_S = 0.01
MAX_SEGMENT_DURATION_S = 3600.0
"""Bounds of one segment's duration, s: shorter is no cut, longer no surgery."""
DEFAULT_EXECUTION_RESERVE_MM = 0.03
"""The contour tolerance a plan leaves for execution when its file gives none, mm (at most
half the tolerance). Measured on the simulated robot (plant ``prototype_plant.toml``, its
encoder offsets at zero, goals led): executing the paper's flap moved the true cut up to
0.025 mm farther from the contour than the plan (ocp-min-time: 0.083 planned, 0.108
executed; toppra 0.000 and 0.030; ocp-min-energy 0.100 and 0.106), mostly where a joint
reverses and its friction changes sign."""
DEFAULT_HOLD_WITHIN_S = 1.0
"""The time within which a feed hold brings the tool to rest on the path when the file
gives none, s (the planners keep the room it needs: :mod:`spm_opt.judge.hold_room`, where the
cost of shorter bounds is measured)."""
MAX_HOLD_WITHIN_S = 60.0
"""Longest hold bound accepted, s: a stop that takes longer is no hold."""
PLAUSIBLE_CONTOUR_TOLERANCE_MM = (0.03, 2.0)
"""The contour tolerances a craniotomy plausibly asks for, mm; a file's value outside is
accepted with a warning (it is likelier a slip of units, µm or m for mm, than meant).
Narrower than 0.03 mm, execution alone uses the tube up: the executed cut strays up to
0.025 mm farther from the contour than the plan (:data:`DEFAULT_EXECUTION_RESERVE_MM`).
Wider than 2 mm, wider than the kerf of a craniotome's cutter (1.5 to 2 mm across): a cut
off by more misses the planned outline by more than its own width, and the flap no longer
fits back in its opening."""

INNER_REACH_MARGIN = 0.05
"""How far past the landmark farthest from the flap's mean direction the inner surface's
smooth radius reaches, rad."""
MIN_LANDMARK_RADIUS = 0.02
"""Smallest distance of a landmark on the skull from the isocenter, m (catches metres
written where millimetres are asked for)."""


@dataclass(frozen=True)
class Limits:
    """Limits every plan must respect (SI). ``None`` means not limited.

    Attributes
    ----------
    max_joint_speed : float, rad/s
    max_joint_acceleration : float or None, rad/s²
    max_joint_jerk : float or None, rad/s³
    max_tool_speed : float or None, m/s
        Speed of the cut point along the skull.
    contour_tolerance : float or None, m
        Largest allowed distance of the cut point from the planned contour (a file's value
        outside :data:`PLAUSIBLE_CONTOUR_TOLERANCE_MM` loads with a warning).
    max_joint_torque : float or None, N·m
        Largest actuator torque (default in files: the actuator's continuous torque).
    execution_reserve : float, m
        The part of the contour tolerance kept for execution: a plan's cut must stay
        within ``contour_tolerance − execution_reserve`` of the contour, the executed cut
        within ``contour_tolerance`` (see :func:`spm_opt.judge.limits.contour_tube`).
    hold_within_s : float or None, s
        A feed hold brings the commanded motion to rest on the path within this time of
        the request, from any point of the plan at full feed; the planners keep the
        acceleration and jerk it needs (:mod:`spm_opt.judge.hold_room`). None: no bound, no room
        kept.
    max_tool_incidence : float or None, rad
        Largest angle between the tool's axis and the skull's outer normal where it cuts.
    min_bone_thickness : float or None, m
        Thinnest bone along the tool's axis a flap may cross (needs the skull's inner mesh).
    max_depth_speed : float or None, m/s
    max_depth_acceleration : float or None, m/s²
        The tool module's limits on its depth setpoint (needs the skull's inner mesh).
    """

    max_joint_speed: float
    max_joint_acceleration: float | None = None
    max_joint_jerk: float | None = None
    max_tool_speed: float | None = None
    contour_tolerance: float | None = None
    max_joint_torque: float | None = None
    execution_reserve: float = 0.0
    hold_within_s: float | None = DEFAULT_HOLD_WITHIN_S
    max_tool_incidence: float | None = None
    min_bone_thickness: float | None = None
    max_depth_speed: float | None = None
    max_depth_acceleration: float | None = None


@dataclass(frozen=True)
class Problem:
    """A cut through landmarks on the skull, for one robot, within limits.

    Attributes
    ----------
    name : str
    robot : Robot
    landmark_names : tuple of str
    landmarks : ndarray, shape (n, 3), m
        Points on the skull (A_i), in visiting order.
    closed : bool
        Whether the cut returns to the first landmark.
    segment_durations : ndarray, shape (segments,), s
        Time from each landmark to the next (used by fixed-time planners).
    limits : Limits
    planner_options : dict
        The problem file's ``[planner.NAME]`` tables, read by each planner.
    source : Path or None
        The problem file, when loaded from one; ``source_sha256`` is its hash.
    skull : Skull or None
        The skull from imaging (its meshes, registration); None: the smooth surface through
        the landmarks stands for it.
    """

    name: str
    robot: Robot
    landmark_names: tuple[str, ...]
    landmarks: np.ndarray
    closed: bool
    segment_durations: np.ndarray
    limits: Limits
    description: str = ""
    planner_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    source: Path | None = None
    source_sha256: str | None = None
    skull: Skull | None = None

    def __post_init__(self) -> None:
        landmarks = np.asarray(self.landmarks, dtype=float)
        object.__setattr__(self, "landmarks", landmarks)
        object.__setattr__(self, "segment_durations", np.asarray(self.segment_durations, float))
        names = self.landmark_names
        if landmarks.ndim != 2 or landmarks.shape[1] != 3 or len(landmarks) < 2:
            raise InputError(
                f"landmarks: expected at least 2 points of 3 coordinates, got {landmarks.shape}"
            )
        if len(landmarks) > MAX_LANDMARKS:
            raise InputError(
                f"landmarks: {len(landmarks):,} of them; expected at most {MAX_LANDMARKS}"
            )
        if len(names) != len(landmarks) or len(set(names)) != len(names):
            raise InputError(
                f"landmark names {excerpt(list(names))}: expected one unique name per landmark"
            )
        for name, point in zip(names, landmarks, strict=True):
            if not np.all(np.isfinite(point)):
                raise InputError(f"landmark {name}: position {point / MM} mm must be finite")
            radius, largest = float(np.linalg.norm(point)), self.robot.lower_arc_radius
            if not MIN_LANDMARK_RADIUS <= radius < largest:
                raise InputError(
                    f"landmark {name}: {radius / MM:g} mm from the isocenter; a point on the "
                    f"skull lies between {MIN_LANDMARK_RADIUS / MM:g} mm and the lower arc's "
                    f"{largest / MM:g} mm (positions are in mm)"
                )
        visits = self.visit_order
        for first, second in zip(visits[:-1], visits[1:], strict=True):
            a, b = landmarks[first], landmarks[second]
            angle = math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b))
            if angle < _SAME_DIRECTION_RAD:
                hint = (
                    " (closed = true returns to the first landmark by itself)"
                    if self.closed
                    else ""
                )
                raise InputError(
                    f"landmarks {names[first]} and {names[second]}: consecutive landmarks lie in "
                    f"the same direction from the isocenter; remove one{hint}"
                )
        durations = self.segment_durations
        if durations.shape != (len(visits) - 1,):
            raise InputError(
                f"segment_durations_s = {excerpt(durations.tolist())}: expected {len(visits) - 1} "
                f"durations, one per segment of the {'closed' if self.closed else 'open'} cut "
                f"through {len(names)} landmarks"
            )
        if not np.all(
            (durations >= MIN_SEGMENT_DURATION_S) & (durations <= MAX_SEGMENT_DURATION_S)
        ):
            raise InputError(
                f"segment_durations_s = {excerpt(durations.tolist())}: expected durations between "
                f"{MIN_SEGMENT_DURATION_S:g} s and {MAX_SEGMENT_DURATION_S:g} s"
            )
        for name, point in zip(names, landmarks, strict=True):
            if point[2] <= 0.0:
                raise UnreachableError(
                    f"landmark {name}: position_mm = {_millimetres(point)}: z = "
                    f"{point[2] / MM:g} mm lies at or below the isocenter plane; the robot "
                    "reaches only z > 0"
                )
        self.robot.check_reachable(self.platform_points, list(names))
        self._check_skull()

    def _check_skull(self) -> None:
        """A skull from imaging: every direction of the cut meets it once, over bone thick
        enough (:mod:`spm_opt.cut.cut_checks`)."""
        skull, limits, thinnest = self.skull, self.limits, self.limits.min_bone_thickness
        for key, value in (
            ("min_bone_thickness_mm", thinnest),
            ("max_depth_speed_mm_s", limits.max_depth_speed),
            ("max_depth_acceleration_mm_s2", limits.max_depth_acceleration),
        ):
            if value is not None and (skull is None or skull.inner_mesh is None):
                raise InputError(
                    f"limits.{key}: expected a [skull] table with an inner_mesh (the bone "
                    "is measured between the two surfaces)"
                )
        if skull is None or skull.outer_mesh is None:
            return
        from spm_opt.cut.cut_checks import check_cut

        tube = self.limits.contour_tolerance
        check_cut(skull.surface, self.contour, self.visit_names, tube, thinnest)

    @property
    def max_joint_torque(self) -> float:
        """The torque limit, N·m: the problem's, else the actuator's continuous torque."""
        return self.limits.max_joint_torque or self.robot.actuator.continuous_torque_nm

    @cached_property
    def fingerprint(self) -> str:
        """SHA-256 (hex) of what a plan must have been made for: the landmarks, whether the
        cut is closed, the limits and the robot (every parameter but its name, its
        actuators' loop parameters, which the executor's lead uses and no plan does, and its
        calibration and built mechanism, which the executor's encoders and the simulated
        robot use: a plan is in the model's joint coordinates).
        Names, descriptions, segment durations, planner options and the file's own bytes
        (its comments, its layout) are left out: a plan made under an equal fingerprint
        keeps the same limits on the same robot through the same landmarks."""
        robot = dataclasses.asdict(self.robot)
        for key in ("name", "mechanism", "calibration", "calibration_record"):
            del robot[key]
        for loop in ("position_loop_gain_per_s", "velocity_loop_bandwidth_per_s"):
            del robot["actuator"][loop]
        what = {
            "landmarks_m": self.landmarks,
            "closed": self.closed,
            "limits": dataclasses.asdict(self.limits),
            "robot": robot,
        }
        if self.skull is not None:
            what["skull"] = self.skull.fingerprint
        text = json.dumps(what, sort_keys=True, default=json_default)
        return hashlib.sha256(text.encode()).hexdigest()

    def record(self) -> dict[str, Any]:
        """What a plan's metadata records of the problem it was made for: its name, its
        file and the file's SHA-256, its :attr:`fingerprint`, and of a skull from imaging
        the fiducial registration error, each fiducial's residual and how far each
        landmark moved onto the mesh."""
        record: dict[str, Any] = {
            "name": self.name,
            "file": None if self.source is None else str(self.source),
            "sha256": self.source_sha256,
            "fingerprint": self.fingerprint,
        }
        skull = self.skull
        if skull is not None:
            record["skull"] = {
                "mesh": skull.outer_mesh is not None,
                "registration_rms_mm": skull.registration_rms_mm,
                "fiducial_residuals_mm": None
                if skull.fiducial_residuals_mm is None
                else skull.fiducial_residuals_mm.tolist(),
                "landmark_shifts_mm": None
                if skull.landmark_shifts_mm is None
                else dict(zip(self.landmark_names, skull.landmark_shifts_mm.tolist(), strict=True)),
            }
        return record

    def along_contour(
        self, arc_lengths_mm: list[float], segment_durations_s: list[float], name: str
    ) -> Problem:
        """An open problem through points of this one's contour at ``arc_lengths_mm`` (mm
        from its first landmark), with ``segment_durations_s`` (s): the same robot, skull
        and limits, for a short run along part of the cut (a dry run, a test)."""
        points = self.contour.point_at(np.asarray(arc_lengths_mm, dtype=float) * MM)
        skull = self.skull
        if skull is not None and skull.landmark_shifts_mm is not None:
            skull = dataclasses.replace(skull, landmark_shifts_mm=np.zeros(len(points)))
        return dataclasses.replace(
            self,
            name=name,
            description=f"{len(points)} points along the contour of {self.name}",
            landmark_names=tuple(f"S{i + 1}" for i in range(len(points))),
            landmarks=points,
            skull=skull,
            closed=False,
            segment_durations=np.asarray(segment_durations_s, dtype=float),
            source=None,
            source_sha256=None,
        )

    @property
    def visit_order(self) -> list[int]:
        """Landmark indices in the order the cut visits them (the first again if closed)."""
        return list(range(len(self.landmarks))) + ([0] if self.closed else [])

    @property
    def visit_names(self) -> list[str]:
        """The landmarks' names in visiting order (a closed cut ends at the first)."""
        return [self.landmark_names[i] for i in self.visit_order]

    @cached_property
    def platform_points(self) -> np.ndarray:
        """Eq. 1: the landmarks projected onto the platform sphere, B_i (n, 3), m."""
        return kinematics.project_landmarks(self.landmarks, self.robot.upper_platform_radius)

    @cached_property
    def landmark_angles(self) -> np.ndarray:
        """Eq. 2: joint angles (n, 2), rad, that put the platform at each B_i."""
        return kinematics.inverse_kinematics(self.platform_points)

    @property
    def waypoint_angles(self) -> np.ndarray:
        """Joint angles (segments + 1, 2), rad, of every landmark visit in order."""
        return self.landmark_angles[self.visit_order]

    @property
    def waypoint_times(self) -> np.ndarray:
        """Times (segments + 1,), s, of the landmark visits under ``segment_durations``."""
        return np.concatenate([[0.0], np.cumsum(self.segment_durations)])

    @cached_property
    def surface(self) -> SkullSurface:
        """The skull's outer surface: the mesh's, or the smooth surface through the
        landmarks."""
        return LandmarkSurface(self.landmarks) if self.skull is None else self.skull.surface

    @cached_property
    def contour(self) -> Contour:
        """The planned cut through the landmarks, on the skull's surface."""
        return Contour(self.landmarks, self.closed, self.surface)

    @cached_property
    def inner_radius(self) -> SmoothRadius | None:
        """The skull's inner surface over the flap, smooth (for the tool's depth), or None
        without an inner mesh."""
        skull = self.skull
        if skull is None or skull.inner_mesh is None:
            return None
        directions = self.landmarks / np.linalg.norm(self.landmarks, axis=1, keepdims=True)
        centre = directions.mean(axis=0)
        centre /= np.linalg.norm(centre)
        reach = float(np.max(np.arccos(np.clip(directions @ centre, -1.0, 1.0))))
        return SmoothRadius(skull.surface.inner_radius, centre, reach + INNER_REACH_MARGIN)

    @cached_property
    def arc_radius_fits(self) -> tuple[ArcRadiusFit, ...]:
        """The skull's radius near each arc of the contour as a smooth polynomial (for the
        optimal-control planners), reaching four tubes' widths off each arc."""
        contour, tube = self.contour, self.limits.contour_tolerance
        radius = float(np.min(np.linalg.norm(self.landmarks, axis=1)))
        across = np.inf if tube is None else 4 * tube / radius
        return tuple(
            fit_arc_radius(
                self.surface,
                contour.start[i],
                contour.inplane[i],
                contour.normal[i],
                float(contour.sweep[i]),
                across,
            )
            for i in range(len(contour.sweep))
        )

    @cached_property
    def segment_lower_bounds(self) -> np.ndarray:
        """Shortest time, s, for each segment between landmark visits that the limits allow
        along the contour (segments,), read-only (:mod:`spm_opt.judge.bounds`)."""
        lower = self.sampled_segment_lower_bounds(SAMPLES_PER_SEGMENT)
        lower.setflags(write=False)
        return lower

    def sampled_segment_lower_bounds(self, samples: int) -> np.ndarray:
        """Shortest time, s, for each segment (segments,), integrating the pace over
        ``samples`` evenly spaced contour points per segment (:mod:`spm_opt.judge.bounds`
        says why it bounds every plan)."""
        contour, limits = self.contour, self.limits
        lower = []
        for start, end in pairwise(contour.landmark_arc_lengths):
            s = np.linspace(start, end, samples)
            q = self.contour_angles(s)
            pace = np.max(np.abs(np.gradient(q, s, axis=0)), axis=1) / limits.max_joint_speed
            if limits.max_tool_speed is not None:
                pace = np.maximum(pace, 1.0 / limits.max_tool_speed)
            lower.append(np.trapezoid(pace, s))
        return np.array(lower)

    def contour_angles(self, s: np.ndarray) -> np.ndarray:
        """Joint angles (N, 2), rad, that put the cut at arc lengths s (N,), m, along the
        contour (the contour's points projected onto the platform sphere, Eqs. 1–2)."""
        points = self.contour.point_at(np.asarray(s, dtype=float))
        radius = self.robot.upper_platform_radius
        return kinematics.inverse_kinematics(kinematics.project_landmarks(points, radius))


def load_problem(path: str | Path, overrides: Mapping[str, Any] | None = None) -> Problem:
    """Read and validate a problem file; its ``robot`` path is relative to the file.

    ``overrides`` replace values before validation, by dotted key in the file's own
    units: ``"limits.max_tool_speed_mm_s"``, ``"segment_durations_s"``, ``"landmarks"``
    (a list of ``{"name", "position_mm"}`` tables), and ``"robot.friction.mu"``,
    ``"robot.payload.mass_kg"`` (keys of the robot file, after ``robot.``).
    """
    path = Path(path)
    data = read_toml(path)
    overrides = dict(overrides or {})
    robot_overrides = {
        key.removeprefix("robot."): overrides.pop(key)
        for key in list(overrides)
        if key.startswith("robot.")
    }
    apply_overrides(data, overrides, str(path))
    root = Table(data, str(path))
    name = root.string("name")
    description = root.string("description", default="")
    robot_key = root.string("robot")
    robot_path = path.parent / robot_key
    if not robot_path.is_file():
        raise root.error("robot", robot_key, f"no robot file at {robot_path}")
    robot = load_robot(robot_path, robot_overrides)
    closed = root.boolean("closed", default=False)
    durations = root.vector(
        "segment_durations_s", minimum=MIN_SEGMENT_DURATION_S, maximum=MAX_SEGMENT_DURATION_S
    )
    skull_keys = read_skull_table(root.table("skull", required=False), path.parent)
    landmarks_file = root.string("landmarks_file", default="")
    names, points = [], []
    if landmarks_file:
        if root.has("landmarks"):
            raise root.error(
                "landmarks_file", landmarks_file, "expected either it or [[landmarks]], not both"
            )
        marked = markup_landmarks(path.parent / landmarks_file, skull_keys, "landmarks_file")
        names, points, closed = list(marked[0]), marked[1], closed or marked[2]
    else:
        for landmark in root.tables("landmarks"):
            names.append(landmark.string("name"))
            points.append(landmark.vector("position_mm", length=3, minimum=-1e3, maximum=1e3) * MM)
            landmark.finish()
    points = np.array(points)
    skull = None
    if skull_keys is not None:
        skull, points = skull_on_mesh(skull_keys, tuple(names), points, landmarks_file)
    limits_table = root.table("limits", required=False)
    limits = _limits(limits_table, robot)
    planners = root.table("planner", required=False)
    options = {key: planners.raw(key) for key in planners.keys()}
    for key, value in options.items():
        if not isinstance(value, dict):
            raise planners.error(key, value, f"expected a table [planner.{key}]")
    limits_table.finish()
    root.finish()
    return _in_file(
        path,
        name=name,
        description=description,
        robot=robot,
        landmark_names=tuple(names),
        landmarks=points,
        closed=closed,
        segment_durations=durations,
        limits=limits,
        planner_options=options,
        source=path,
        source_sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
        skull=skull,
    )


def _in_file(path: Path, **fields: Any) -> Problem:
    """The problem of these fields, read from ``path``: an error names the file."""
    try:
        return Problem(**fields)
    except InputError as error:
        raise type(error)(f"{path}: {error}") from None


def _degrees(value: float | None) -> float | None:
    """A file's angle in degrees, or None, in rad."""
    return None if value is None else math.radians(value)


def _millimetres_or_none(value: float | None) -> float | None:
    """A file's length in mm, or None, in m."""
    return None if value is None else value * MM


def _millimetres(point: np.ndarray) -> str:
    """A point, m, as the file gives it: ``[x, y, z]`` in mm."""
    return "[" + ", ".join(f"{value / MM:g}" for value in point) + "]"


def _limits(table: Table, robot: Robot) -> Limits:
    positive = {"minimum": 0.0, "exclusive_minimum": True, "default": None}
    speed_rpm = table.number("max_joint_speed_rpm", **positive)
    actuator_speed = robot.actuator.continuous_speed_rad_s
    if speed_rpm is not None and speed_rpm * RPM > actuator_speed * (1 + 1e-9):
        raise table.error(
            "max_joint_speed_rpm",
            speed_rpm,
            f"expected at most the actuator's continuous speed, {actuator_speed / RPM:g} rpm",
        )
    tool_speed = table.number("max_tool_speed_mm_s", **positive)
    tolerance = table.number("contour_tolerance_mm", **positive)
    low, high = PLAUSIBLE_CONTOUR_TOLERANCE_MM
    if tolerance is not None and not low <= tolerance <= high:
        _LOG.warning(
            "%s = %g: outside the plausible range for a craniotomy, %g to %g mm (units?)",
            table.name("contour_tolerance_mm"),
            tolerance,
            low,
            high,
        )
    torque = table.number("max_joint_torque_nm", **positive)
    actuator_torque = robot.actuator.continuous_torque_nm
    if torque is not None and torque > actuator_torque * (1 + 1e-9):
        raise table.error(
            "max_joint_torque_nm",
            torque,
            f"expected at most the actuator's continuous torque, {actuator_torque:g} N·m",
        )
    reserve = table.number("execution_reserve_mm", minimum=0.0, default=None)
    if tolerance is None:
        if reserve:
            raise table.error(
                "execution_reserve_mm",
                reserve,
                "expected no reserve without a contour_tolerance_mm",
            )
        reserve = 0.0
    elif reserve is None:  # the default, leaving a plan at least half of a narrow tube
        reserve = min(DEFAULT_EXECUTION_RESERVE_MM, 0.5 * tolerance)
    elif reserve >= tolerance:
        raise table.error(
            "execution_reserve_mm",
            reserve,
            f"expected less than contour_tolerance_mm ({tolerance:g}): a plan must keep "
            "some of the tube",
        )
    return Limits(
        max_joint_speed=actuator_speed if speed_rpm is None else speed_rpm * RPM,
        max_joint_acceleration=table.number("max_joint_acceleration_rad_s2", **positive),
        max_joint_jerk=table.number("max_joint_jerk_rad_s3", **positive),
        max_tool_speed=None if tool_speed is None else tool_speed * MM,
        contour_tolerance=None if tolerance is None else tolerance * MM,
        max_joint_torque=actuator_torque if torque is None else torque,
        execution_reserve=reserve * MM,
        max_tool_incidence=_degrees(
            table.number("max_tool_incidence_deg", **positive, maximum=90.0)
        ),
        min_bone_thickness=_millimetres_or_none(table.number("min_bone_thickness_mm", **positive)),
        hold_within_s=table.number(
            "hold_within_s",
            minimum=0.0,
            exclusive_minimum=True,
            maximum=MAX_HOLD_WITHIN_S,
            default=DEFAULT_HOLD_WITHIN_S,
        ),
    )
