"""Write docs/reference/files.md, the reference of every key of the problem, robot and sweep
files and of every planner's ``[planner.NAME]`` settings, from the code that reads them.

    python docs/scripts/file_reference.py

The keys come from loading the repository's own files (``problems/*.toml``,
``problems/robots/*.toml``, ``problems/sweeps/*.toml``, and two files that take paths no
shipped file takes: :func:`other_paths`) under :func:`spm_opt.base.fields.recording`: every
key the loaders ask for, present in the file or not, with its reader's default, bounds and
choices.
The planner settings come from each registered planner reading them, with the registry's
``planner_options`` and ``settings_from_options`` watched. ``tests/test_docs_reference.py``
checks that the page is up to date and lists every key the loaders accept.
"""

from __future__ import annotations

import contextlib
import inspect
import sys
import tempfile
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from unittest import mock

import tomli_w

from spm_opt.base.fields import KeyRecord, recording
from spm_opt.model.params import CALIBRATION_NUMBERS, CALIBRATION_STRINGS, load_robot
from spm_opt.planners import PLANNERS
from spm_opt.problem.problem import PLAUSIBLE_CONTOUR_TOLERANCE_MM as _TOLERANCE_MM
from spm_opt.problem.problem import load_problem
from spm_opt.studies.sweep.spec import load_sweep_spec

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "reference" / "files.md"
PAPER_PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"
PROTOTYPE = ROOT / "problems" / "robots" / "prototype.toml"

RANDOM_SWEEP = """\
name = "random_axes"
problem = "{problem}"
planners = ["cubic"]

[random]
samples = 2

[random.ranges]
"limits.max_tool_speed_mm_s" = [2.0, 4.0]
"""
"""A sweep with a ``[random]`` table, so that its keys are read too."""

CALIBRATION = {
    "encoder_zero_deg": [0.05, -0.03],
    **dict.fromkeys(CALIBRATION_STRINGS, "text"),
    **dict.fromkeys(CALIBRATION_NUMBERS, 1.0),
    "standard_error_deg": {"encoder_zero_1": 0.002},
    "unidentified": [],
}
"""A ``[calibration]`` table with every key its reader takes."""

OPEN_TABLES = {
    "problem": {"planner": "NAME"},
    "sweep": {"grid": "KEY", "random.ranges": "KEY"},
    "robot": {"calibration.standard_error_deg": "PARAMETER"},
}
"""Tables whose keys are names, not fixed keys: every key under them is shown as one."""

UNITS = (
    ("_nm_s_per_rad", "N·m·s/rad"),
    ("_kg_m2", "kg·m²"),
    ("_rad_s2", "rad/s²"),
    ("_rad_s3", "rad/s³"),
    ("_rad_s", "rad/s"),
    ("_mm_s", "mm/s"),
    ("_per_s", "1/s"),
    ("_deg", "°"),
    ("_rpm", "rpm"),
    ("_mm", "mm"),
    ("_kg", "kg"),
    ("_nm", "N·m"),
    ("_s", "s"),
    ("_a", "A"),
)
"""Key endings and their units, longest first."""

KINDS = {
    "number": "number",
    "vector": "list of numbers",
    "string": "string",
    "boolean": "true or false",
    "table": "table",
    "tables": "array of tables",
    "raw": "see the meaning",
    "has": "see the meaning",
}

NOTES = {
    ("problem", "name"): "The problem's name, in reports.",
    ("problem", "description"): "One line about the problem.",
    ("problem", "robot"): "The robot file, relative to this file.",
    ("problem", "closed"): "Whether the cut returns to the first landmark.",
    ("problem", "segment_durations_s"): "Time from each landmark visit to the next, one per "
    "segment (n − 1 for n landmarks, n when closed); fixed-time planners keep them.",
    ("problem", "landmarks"): "The landmarks on the skull, in visiting order (at least 2).",
    ("problem", "landmarks[].name"): "A unique name (A1, A2, ...).",
    ("problem", "landmarks[].position_mm"): "The point on the skull, from the isocenter; "
    "above the isocenter plane (z > 0) and within the robot's reach.",
    ("problem", "limits"): "The limits every plan is judged by; every key is optional.",
    ("problem", "limits.max_joint_speed_rpm"): "Absent: the actuator's continuous speed "
    "(13.7 rpm for the L54-50-S500-R); at most that.",
    ("problem", "limits.max_joint_acceleration_rad_s2"): "Absent: not limited.",
    ("problem", "limits.max_joint_jerk_rad_s3"): "Absent: not limited.",
    ("problem", "limits.max_tool_speed_mm_s"): "Speed of the cut point along the skull. "
    "Absent: not limited.",
    ("problem", "limits.contour_tolerance_mm"): "Largest distance of the cut from the planned "
    "contour. Absent: landmarks must be met within 0.1 mm and the tube is not checked. "
    f"Plausible: {_TOLERANCE_MM[0]:g} to {_TOLERANCE_MM[1]:g} mm; outside, a warning (a slip "
    "of units?): narrower, execution alone uses the tube up (the executed cut strays up to "
    "0.025 mm farther than the plan); wider, the cut may miss its outline by more than a "
    "craniotome's kerf (1.5 to 2 mm), and the flap no longer fits back.",
    ("problem", "limits.max_joint_torque_nm"): "Absent: the actuator's continuous torque "
    "(14 N·m); at most that.",
    ("problem", "limits.execution_reserve_mm"): "The part of the tolerance a plan leaves for "
    "execution: a plan must keep within tolerance − reserve. Absent: 0.03 mm, or half the "
    "tolerance if less; less than the tolerance; only with a tolerance.",
    ("problem", "limits.hold_within_s"): "A feed hold rests on the path within this time; "
    "the planners keep the room it needs.",
    ("problem", "limits.max_tool_incidence_deg"): "Largest angle between the tool's axis and "
    "the skull's outer normal where it cuts (a craniotome cuts badly into oblique bone); "
    "judged by the evaluator. Absent: not limited.",
    ("problem", "limits.min_bone_thickness_mm"): "Thinnest bone along the tool's axis the cut "
    "may cross; a thinner stretch refuses the problem at loading. Needs skull.inner_mesh.",
    ("problem", "limits.max_depth_speed_mm_s"): "The tool module's speed limit on its depth "
    "setpoint; judged by the evaluator. Needs skull.inner_mesh.",
    ("problem", "limits.max_depth_acceleration_mm_s2"): "The tool module's acceleration limit "
    "on its depth setpoint; judged by the evaluator. Needs skull.inner_mesh.",
    ("problem", "landmarks_file"): "Instead of [[landmarks]]: a 3D Slicer markups file "
    "(.mrk.json: a Fiducial list, Curve or ClosedCurve, in LPS or RAS, mm or um), relative to "
    "this file, read in its order; a ClosedCurve makes the cut closed. Needs [skull]'s "
    "transform.",
    ("problem", "skull"): "The patient's skull from imaging: meshes, their frame and the "
    "transform into the robot's frame.",
    ("problem", "skull.outer_mesh"): "The skull's outer surface: any mesh trimesh reads (STL, "
    "PLY, OBJ, OFF), in mm, in `frame`, relative to this file. The tool cuts where its axis "
    "meets it; landmarks are moved along their directions onto it.",
    ("problem", "skull.inner_mesh"): "The skull's inner surface, like outer_mesh: the bone's "
    "thickness and the tool's depth setpoint.",
    ("problem", "skull.frame"): "The meshes' (and fiducials') frame: RAS or LPS; a mesh whose "
    "header says SPACE=... must agree.",
    ("problem", "skull.image_to_robot"): "4×4 rigid transform from the image's RAS "
    "coordinates to the robot's frame, mm (a mesh in LPS is turned to RAS first).",
    ("problem", "skull.depth_margin_mm"): "The tool tip's depth setpoint lies this far outside "
    "the inner surface (negative: past it).",
    ("problem", "skull.max_landmark_shift_mm"): "The farthest a landmark may be moved along "
    "its direction from the isocenter onto the outer mesh; a landmark farther from the mesh "
    "(placed on the scalp, in another frame or unit, on another skull) is refused, named. "
    "Points placed on the bone in the image lie within a voxel or two of its mesh.",
    ("problem", "skull.registration"): "Instead of image_to_robot: fiducials in both frames, "
    "fitted by a rigid least-squares registration; its RMS error and each fiducial's "
    "residual go into the plan's metadata.",
    ("problem", "skull.registration.image_fiducials_mm"): "At least 3 points, not near one "
    "line (condition number, their spread along their line over their spread across it, at "
    "most 10), in `frame`.",
    ("problem", "skull.registration.robot_fiducials_mm"): "The same points in the robot's "
    "frame, in the same order.",
    ("problem", "skull.registration.max_fiducial_residual_mm"): "The largest residual allowed: "
    "the distance between a robot fiducial and its image fiducial once the fit is applied. A "
    "larger one (a fiducial located wrongly in one frame) refuses the fit, naming the "
    "fiducial and every residual.",
    ("problem", "planner"): "Settings of the planners, one table each.",
    ("problem", "planner.NAME"): "The settings of the planner NAME: see Planner settings.",
    ("robot", "name"): "The robot's name.",
    ("robot", "description"): "One line about the robot.",
    ("robot", "actuator"): "The two actuators (both the same model).",
    ("robot", "actuator.model"): "The actuator's datasheet.",
    ("robot", "actuator.current_a"): "Current → torque map: currents, rising strictly from "
    "0, one per torque_nm (at least 2). Absent with torque_nm: the datasheet's map.",
    ("robot", "actuator.torque_nm"): "Current → torque map: the torques at current_a, "
    "rising strictly from 0.",
    ("robot", "actuator.rotor_inertia_kg_m2"): "Reflected rotor inertia of each drive.",
    ("robot", "actuator.gear_efficiency"): "η: the load gets η τ from a driving motor, τ / η back.",
    ("robot", "actuator.viscous_friction_nm_s_per_rad"): "Viscous friction in each joint (θ1, θ2).",
    ("robot", "actuator.coulomb_friction_nm"): "Coulomb friction in each joint (θ1, θ2).",
    ("robot", "actuator.position_loop_gain_per_s"): "Kp of each actuator's position loop "
    "(θ1, θ2); the executor leads its goals by it. Absent: the datasheet's.",
    ("robot", "actuator.velocity_loop_bandwidth_per_s"): "ωv of each actuator's velocity "
    "loop (θ1, θ2). Absent: the datasheet's.",
    ("robot", "friction"): "Coulomb friction of the platforms on their rails.",
    ("robot", "friction.mu"): "Friction coefficient (0.24: Teflon on aluminium).",
    ("robot", "friction.smoothing_rad_s"): "Sliding rate below which the optimisers see a "
    "smooth sign; evaluation uses the exact one.",
    ("robot", "joints"): "The joints' range and the singularity margin.",
    ("robot", "joints.theta1_range_deg"): "[lower, upper] of θ1, lower < upper.",
    ("robot", "joints.theta2_range_deg"): "[lower, upper] of θ2, lower < upper.",
    ("robot", "joints.min_singularity_margin"): "Smallest allowed singularity margin (1 at "
    "θ = 0, 0 at a singularity).",
    ("robot", "joints.encoder_offset_deg"): "What each encoder of the robot as built reads "
    "at θ = 0; only the simulated robot applies it (a plant whose encoders are off). A "
    "calibration writes the zeros it found here too.",
    ("robot", "mechanism"): "The mechanism as built, for the simulated robot: its tool points "
    "where these error angles say (0: the ideal robot). A calibration writes what it found.",
    ("robot", "mechanism.axis_twist_deg"): "The lower actuator's axis turned about z from y "
    "(the axes 90° + twist apart).",
    ("robot", "mechanism.arc_tilt_deg"): "[upper, lower]: each arc's plane normal tilted "
    "towards its actuator's axis.",
    ("robot", "mechanism.tool_tilt_deg"): "[x, y]: the tool's axis turned about the upper "
    "platform's x, then y, from the platform's radius.",
    ("robot", "calibration"): "What `spm-opt calibrate` measured: the executor's goals and "
    "readings go through it, so plans stay in the ideal model's joint coordinates. Absent: "
    "the ideal robot.",
    ("robot", "calibration.encoder_zero_deg"): "What each encoder reads at θ = 0.",
    ("robot", "calibration.axis_twist_deg"): "As mechanism.axis_twist_deg, measured.",
    ("robot", "calibration.arc_tilt_deg"): "As mechanism.arc_tilt_deg, measured.",
    ("robot", "calibration.tool_tilt_deg"): "As mechanism.tool_tilt_deg, measured.",
    ("robot", "calibration.date"): "When the calibration was fitted (UTC).",
    ("robot", "calibration.data_sha256"): "SHA-256 of the log and tracker file it was fitted to.",
    ("robot", "calibration.tracker"): "The tracker's file, or the simulated tracker's settings.",
    ("robot", "calibration.method"): "How it was fitted.",
    ("robot", "calibration.marker_distance_mm"): "The marker's fitted distance from the isocenter.",
    ("robot", "calibration.poses"): "Poses fitted.",
    ("robot", "calibration.held_out_poses"): "Poses never fitted, on which it was judged.",
    ("robot", "calibration.residual_rms_mm"): "The fit's residual (FRE).",
    ("robot", "calibration.held_out_rms_mm"): "The error at the held-out poses (TRE, "
    "measured), the tracker's own error included.",
    ("robot", "calibration.held_out_max_mm"): "The largest held-out error.",
    ("robot", "calibration.predicted_tre_mm"): "Fitzpatrick's TRE of the rigid registration "
    "from the fit's localisation error.",
    ("robot", "calibration.condition_number"): "Of the fitted poses' scaled identification "
    "Jacobian.",
    ("robot", "calibration.standard_error_deg"): "Each identified error angle's standard error.",
    ("robot", "calibration.unidentified"): "Error angles the poses could not separate (kept at 0).",
    ("robot", "payload"): "A tool carried by the upper platform.",
    ("robot", "payload.mass_kg"): "Its mass, a point mass.",
    ("robot", "payload.offset_mm"): "Its offset from B in the upper platform's frame.",
    ("sweep", "name"): "The sweep's name.",
    ("sweep", "description"): "One line about the sweep; the summary's title.",
    ("sweep", "problem"): "The base problem file, relative to this file.",
    ("sweep", "planners"): "A non-empty list of registered planner names, each once.",
    ("sweep", "grid"): "Axes swept in every combination.",
    ("sweep", "grid.KEY"): "A non-empty list of values, each once (2 and 2.0 are one), of a "
    "problem key "
    "(limits.max_tool_speed_mm_s, segment_durations_s) or robot.KEY of its robot file "
    "(robot.friction.mu); each value must load.",
    ("sweep", "random"): "Axes drawn at random (uniform), seeded.",
    ("sweep", "random.samples"): "Draws of every range; a whole number.",
    ("sweep", "random.seed"): "A whole number.",
    ("sweep", "random.ranges"): "At least one KEY = [low, high].",
    ("sweep", "random.ranges.KEY"): "[low, high], low < high, of a key as in [grid], not "
    "also a [grid] axis.",
    ("sweep", "flaps"): "Random bone flaps, seeded.",
    ("sweep", "flaps.count"): "How many flaps; a whole number.",
    ("sweep", "flaps.seed"): "A whole number.",
    ("sweep", "flaps.size_mm"): "[low, high] of the flap's size (its largest distance "
    "between two landmarks), 0 < low ≤ high.",
    ("sweep", "flaps.landmarks"): "Landmarks per flap: a whole number in [3, 12], or "
    "[low, high] of them, drawn per flap. Absent: 4.",
    ("sweep", "flaps.tool_speed_mm_s"): "Mean tool speed the segment durations give; at "
    "most 2/3 of a drawn tool-speed limit.",
    ("sweep", "flaps.contour_tolerance_mm"): "[low, high], 0 < low ≤ high: each flap draws "
    "its limits.contour_tolerance_mm (log-uniform). Absent: the base problem's.",
    ("sweep", "flaps.max_tool_speed_mm_s"): "[low, high], 0 < low ≤ high: each flap draws "
    "its limits.max_tool_speed_mm_s. Absent: the base problem's.",
}
"""What each key means, by (file kind, key); keys of robot bodies are in BODY_NOTES."""

BODY_NOTES = {
    "": "A rigid body: upper_platform and lower_platform carry the tool guide, upper_arc "
    "and lower_arc are the input arcs.",
    "mass_kg": "Its mass.",
    "com_radius_mm": "Distance of its mass centre from the isocenter (along B for a "
    "platform, along the arc's symmetry axis for an arc).",
    "inertia_kg_m2": "3×3 inertia about the mass centre, in the body frame: symmetric, "
    "positive semi-definite.",
    "rail_radius_mm": "The arc's rail radius (arcs only).",
}
BODIES = ("upper_platform", "lower_platform", "upper_arc", "lower_arc")


@dataclass(frozen=True)
class Entry:
    """One documented key: the merged records of every read of it."""

    key: str
    kind: str
    required: bool
    record: KeyRecord


@dataclass(frozen=True)
class PlannerSettings:
    """One planner's ``[planner.NAME]`` settings, as its code reads them."""

    name: str
    keys: tuple[str, ...]
    defaults: Any = None
    ranges: dict[str, tuple[float, float]] | None = None
    choices: dict[str, tuple[str, ...]] | None = None


def shipped_files() -> dict[str, list[Path]]:
    """The repository's problem, robot and sweep files, by kind."""
    problems = ROOT / "problems"
    return {
        "problem": sorted(problems.glob("*.toml")),
        "robot": sorted((problems / "robots").glob("*.toml")),
        "sweep": sorted((problems / "sweeps").glob("*.toml")),
    }


LOADERS: dict[str, Callable[[Path], Any]] = {
    "problem": load_problem,
    "robot": load_robot,
    "sweep": load_sweep_spec,
}


def other_paths(folder: Path) -> dict[str, list[Path]]:
    """Files, written in ``folder``, that take the loaders' paths no shipped file takes: a
    sweep with ``[random]``, a robot without a current map, one with a ``[calibration]``,
    and a problem whose skull's transform is fitted to fiducials."""
    sweep = folder / "random_axes.toml"
    sweep.write_text(RANDOM_SWEEP.format(problem=PAPER_PROBLEM.as_posix()), encoding="utf-8")
    robot = tomllib.loads(PROTOTYPE.read_text(encoding="utf-8"))
    for key in ("current_a", "torque_nm"):
        del robot["actuator"][key]
    datasheet_map = folder / "datasheet_map.toml"
    datasheet_map.write_text(tomli_w.dumps(robot), encoding="utf-8")
    robot["calibration"] = CALIBRATION
    calibrated = folder / "calibrated.toml"
    calibrated.write_text(tomli_w.dumps(robot), encoding="utf-8")
    problem = tomllib.loads(PAPER_PROBLEM.read_text(encoding="utf-8"))
    problem["robot"] = PROTOTYPE.as_posix()
    fiducials = [[0.0, 0.0, 0.0], [50.0, 0.0, 0.0], [0.0, 40.0, 0.0], [0.0, 0.0, 30.0]]
    problem["skull"] = {
        "frame": "RAS",
        "registration": {"image_fiducials_mm": fiducials, "robot_fiducials_mm": fiducials},
    }
    registered = folder / "registered.toml"
    registered.write_text(tomli_w.dumps(problem), encoding="utf-8")
    return {"problem": [registered], "robot": [datasheet_map, calibrated], "sweep": [sweep]}


def records_by_kind() -> dict[str, list[KeyRecord]]:
    """Every key read from each kind of file when loading the shipped files and
    :func:`other_paths`: only the reads of that file itself, not of files it refers to."""
    files = shipped_files()
    found: dict[str, list[KeyRecord]] = {}
    with tempfile.TemporaryDirectory() as folder:
        for kind, paths in other_paths(Path(folder)).items():
            files[kind] += paths
        for kind, paths in files.items():
            found[kind] = []
            for path in paths:
                with recording() as records:
                    LOADERS[kind](path)
                found[kind] += [r for r in records if r.source == str(path)]
    return found


def _open_key(kind: str, key: str) -> str:
    """``key`` with a name under one of :data:`OPEN_TABLES` shown as its placeholder."""
    for table, placeholder in OPEN_TABLES.get(kind, {}).items():
        if key.startswith(table + "."):
            return f"{table}.{placeholder}"
    return key


def entries(kind: str, records: list[KeyRecord]) -> list[Entry]:
    """One entry per key, each table's keys after it, in the order the loader first reads
    them. A key read as ``raw`` and typed later is the typed read; a key is required only
    if every read of it requires it (one the loader asks about with ``has`` first, or a
    name in an open table, is not)."""
    grouped: dict[str, list[KeyRecord]] = {}
    for record in records:
        grouped.setdefault(_open_key(kind, record.key), []).append(record)
    tops = list(dict.fromkeys(_top(key) for key in grouped))
    result = []
    for key, reads in sorted(grouped.items(), key=lambda item: tops.index(_top(item[0]))):
        typed = [r for r in reads if r.kind not in ("raw", "has")] or reads
        optional = next((r for r in reads if not r.required), None)
        record = typed[0] if optional is None else replace(typed[0], default=optional.default)
        required = all(r.required for r in reads) and not _is_open(kind, key)
        result.append(Entry(key, typed[0].kind, required, record))
    return result


def _top(key: str) -> str:
    """The top-level table of a dotted key (``landmarks`` of ``landmarks[].name``)."""
    return key.split(".")[0].split("[")[0]


def _is_open(kind: str, key: str) -> bool:
    """Whether ``key`` stands for any name in an open table."""
    return any(key == f"{t}.{p}" for t, p in OPEN_TABLES.get(kind, {}).items())


def _recording_calls(module: Any, name: str, calls: list[dict[str, Any]]) -> Any:
    """Patch ``module.name`` with a wrapper that appends each call's arguments, by name, to
    ``calls`` and then calls the original."""
    original = getattr(module, name)
    signature = inspect.signature(original)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        calls.append(dict(bound.arguments))
        return original(*args, **kwargs)

    return mock.patch.object(module, name, wrapper)


@contextlib.contextmanager
def _watching_planners() -> Iterator[tuple[list[dict[str, Any]], list[dict[str, Any]]]]:
    """Record every call of ``planner_options`` and ``settings_from_options`` that the
    planner modules make, each as its arguments by name."""
    options: list[dict[str, Any]] = []
    settings: list[dict[str, Any]] = []
    modules = [
        module
        for name, module in sorted(sys.modules.items())
        if name.startswith("spm_opt.planners.") and hasattr(module, "planner_options")
    ]
    with contextlib.ExitStack() as stack:
        for module in modules:
            stack.enter_context(_recording_calls(module, "planner_options", options))
            if hasattr(module, "settings_from_options"):
                stack.enter_context(_recording_calls(module, "settings_from_options", settings))
        yield options, settings


def planner_settings() -> list[PlannerSettings]:
    """Every registered planner's settings, read by the planner itself from the paper's
    problem (its ``settings`` method, or ``plan`` for a planner without one)."""
    problem = load_problem(PAPER_PROBLEM)
    found = []
    for name in sorted(PLANNERS):
        planner = PLANNERS[name]
        with _watching_planners() as (options, settings):
            getattr(planner, "settings", planner.plan)(problem)
        allowed = {tuple(call["allowed"]) for call in options if call["name"] == name}
        if len(allowed) != 1:
            raise RuntimeError(f"{name}: read its [planner.{name}] table {len(allowed)} ways")
        read = next((call for call in settings if call["planner"] == name), None)
        if read is None:
            found.append(PlannerSettings(name, allowed.pop()))
            continue
        found.append(
            PlannerSettings(name, allowed.pop(), read["defaults"], read["ranges"], read["choices"])
        )
    return found


def _number(value: Any) -> str:
    """A value as a TOML file would give it: whole numbers in full."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int) or (isinstance(value, float) and value.is_integer()):
        return f"{value:.0f}" if abs(value) < 1e15 else f"{value:g}"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _default(entry: Entry) -> str:
    if entry.required:
        return "required"
    default = entry.record.default
    if default is None or (entry.kind == "table" and default == {}):
        return "—"
    if isinstance(default, str):
        return f'`"{default}"`'
    if hasattr(default, "__len__"):
        return "`[" + ", ".join(_number(v) for v in default) + "]`"
    return f"`{_number(default)}`"


def _allowed(record: KeyRecord) -> str:
    if record.choices:
        return "one of " + ", ".join(f'`"{c}"`' for c in record.choices)
    low, high = record.minimum, record.maximum
    below = "<" if record.exclusive_minimum else "≤"
    if low is not None and high is not None:
        bounds = f"{_number(low)} {below} x ≤ {_number(high)}"
    elif low is not None:
        bounds = f"x {'>' if record.exclusive_minimum else '≥'} {_number(low)}"
    elif high is not None:
        bounds = f"x ≤ {_number(high)}"
    else:
        bounds = ""
    if record.kind == "vector":
        count = f"{record.length} numbers" if record.length else "numbers"
        return count + (f", each {bounds}" if bounds else "")
    return bounds or "—"


def unit(key: str) -> str:
    """The unit a key's name ends in, or — for none."""
    last = key.rsplit(".", 1)[-1]
    return next((u for ending, u in UNITS if last.endswith(ending)), "—")


def note(kind: str, key: str) -> str:
    """What ``key`` means (:data:`NOTES`, :data:`BODY_NOTES`)."""
    body, _, rest = key.partition(".")
    if kind == "robot" and body in BODIES:
        return BODY_NOTES[rest]
    return NOTES.get((kind, key), "")


def key_table(kind: str, found: list[Entry]) -> list[str]:
    """The markdown table of one kind of file."""
    lines = ["| key | type | unit | default | allowed | meaning |", "|---|---|---|---|---|---|"]
    for entry in found:
        cells = [
            f"`{entry.key}`",
            KINDS[entry.kind],
            unit(entry.key),
            _default(entry),
            _allowed(entry.record),
            note(kind, entry.key),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def attribute_notes(cls: type) -> dict[str, str]:
    """Each attribute's description from the numpy-style "Attributes" section of ``cls``'s
    docstring (``a, b : float`` describes both)."""
    lines = inspect.getdoc(cls).splitlines()
    start = lines.index("Attributes") + 2 if "Attributes" in lines else len(lines)
    notes: dict[str, str] = {}
    names: list[str] = []
    for line in lines[start:]:
        if line and not line.startswith(" "):
            names = [name.strip() for name in line.split(" : ")[0].split(",")]
            notes.update(dict.fromkeys(names, ""))
        elif line.strip():
            for name in names:
                notes[name] = f"{notes[name]} {line.strip()}".strip()
    return {name: text.replace("``", "`") for name, text in notes.items()}


def settings_table(settings: PlannerSettings) -> list[str]:
    """The markdown lines of one planner's settings."""
    lines = [f"### `{settings.name}`", ""]
    if not settings.keys:
        return [*lines, f"Takes no settings: a `[planner.{settings.name}]` table must be empty."]
    settings_class = type(settings.defaults)
    notes = attribute_notes(settings_class)
    lines += [
        f"Read into `{settings_class.__module__}.{settings_class.__name__}`.",
        "",
        "| key | type | unit | default | allowed | meaning |",
        "|---|---|---|---|---|---|",
    ]
    choices = settings.choices or {}
    for key in settings.keys:
        default = getattr(settings.defaults, key)
        if key in choices:
            kind, allowed = "string", "one of " + ", ".join(f'`"{c}"`' for c in choices[key])
            shown = f'`"{default}"`'
        else:
            low, high = settings.ranges[key]
            kind = "integer" if isinstance(default, int) else "number"
            allowed = f"{_number(low)} ≤ x ≤ {_number(high)}"
            shown = f"`{_number(default)}`"
        cells = [f"`{key}`", kind, unit(key), shown, allowed, notes.get(key, "")]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


HEADER = """\
# Problem, robot and sweep files

<!-- Generated by `python docs/scripts/file_reference.py` from the code that reads these
files; do not edit by hand. tests/test_docs_reference.py checks that it is up to date. -->

Every file is TOML with the unit in the key's name (`position_mm`, `segment_durations_s`,
`max_joint_speed_rpm`); everything is SI inside. A key the loader does not know is an
error naming the closest known key, and a value out of range is an error naming the key,
the value and what is allowed: one line, exit status 2.

In the tables: *required* keys must be given; *—* as a default means the key may be left
out, with the effect the meaning says. `x` stands for the value; for a list, each of its
numbers. `[]` marks an array of tables (`[[landmarks]]`); `NAME` and `KEY` stand for
names of your own.
"""

SECTIONS = {
    "problem": (
        "Problem files",
        "`problems/*.toml`: a cut through landmarks on the skull, for one robot, within "
        "limits (`spm_opt.load_problem`). Overrides (`load_problem(path, overrides)` and "
        "the sweeps' axes) use the same dotted keys, with `robot.` before a key of the "
        "robot file.",
    ),
    "robot": (
        "Robot files",
        "`problems/robots/*.toml`: the geometry, masses, friction, joint range and "
        "actuators of one robot (`spm_opt.load_robot`). `spm-opt identify` writes one.",
    ),
    "sweep": (
        "Sweep specifications",
        "`problems/sweeps/*.toml`: a base problem, the planners and the axes to vary "
        "(`spm-opt sweep`). A file needs at least one of `[grid]`, `[random]` and "
        "`[flaps]` to sweep anything; every task is one combination of their values with "
        "one planner.",
    ),
}

PLANNER_INTRO = """\
## Planner settings

A problem file's `[planner.NAME]` table sets the planner NAME's settings; every key is
optional and a key the planner does not know is an error listing the ones it does. The
defaults are each planner's own (the optimal-control planners share one set of keys with
different defaults). A setting that must be a whole number is an integer.
"""


def render() -> str:
    """The whole page."""
    lines = [HEADER]
    for kind, records in records_by_kind().items():
        title, intro = SECTIONS[kind]
        lines += [f"## {title}", "", intro, "", *key_table(kind, entries(kind, records)), ""]
    lines.append(PLANNER_INTRO)
    for settings in planner_settings():
        lines += [*settings_table(settings), ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def main() -> None:
    PAGE.parent.mkdir(parents=True, exist_ok=True)
    PAGE.write_text(render(), encoding="utf-8")
    print(PAGE.relative_to(ROOT))


if __name__ == "__main__":
    main()
