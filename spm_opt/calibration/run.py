"""The calibration from end to end: the poses chosen, the plan run by the one executor, the
log's readings and the tracker's still windows paired, the fit, the robot file written.

The run goes through the robot as its encoders read (its ``[calibration]`` set aside), so
the log's positions are the encoders' readings, which the fit needs. Each pose's reading is
the mean of the log's measured positions over its dwell (after the settling time); each
pose's marker position the mean of the tracker's still window of the same rank
(:mod:`spm_opt.calibration.dwell`): the tracker needs no clock shared with the robot.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from spm_opt.base.errors import InputError
from spm_opt.calibration import design
from spm_opt.calibration.dwell import dwell_means
from spm_opt.calibration.fit import CalibrationFit, HeldOut, PoseMeasurements, fit, held_out
from spm_opt.calibration.measurement import UNKNOWNS
from spm_opt.model import geometry, kinematics
from spm_opt.model.geometry import IDEAL, PARAMETERS, Geometry
from spm_opt.model.params import Robot
from spm_opt.problem.problem import Problem
from spm_opt.verify.motion_capture import MarkerTrack

MM = 1e-3


@dataclass(frozen=True)
class CalibrationSettings:
    """How a calibration is planned (deg, s, mm; counts of poses).

    ``poses`` are chosen by the D-optimal design from a ``pool_per_axis``² grid within
    ±``reach_deg``; ``held_out`` more are drawn at random (seeded) from the rest of the pool
    and never fitted; each dwell lasts ``dwell_s``, its first ``settle_s`` not averaged.
    """

    poses: int = 40
    held_out: int = 8
    reach_deg: float = 55.0
    pool_per_axis: int = 15
    dwell_s: float = 2.0
    settle_s: float = 0.8
    marker_distance_mm: float = 200.0
    seed: int = 0


def choose_poses(robot: Robot, settings: CalibrationSettings) -> tuple[np.ndarray, np.ndarray]:
    """The poses (n, 2), rad, the design chooses and the held-out ones after them, and a
    mask (n,) of the held-out."""
    pool = design.pose_pool(robot, math.radians(settings.reach_deg), settings.pool_per_axis)
    chosen = design.d_optimal(pool, settings.poses, settings.marker_distance_mm * MM)
    rest = np.setdiff1d(np.arange(len(pool)), chosen)
    if settings.held_out > len(rest):
        raise InputError(
            f"calibration held_out = {settings.held_out}; allowed: at most the pool's "
            f"{len(rest)} poses the design left"
        )
    rng = np.random.default_rng(settings.seed)
    extra = rng.choice(rest, settings.held_out, replace=False)
    poses = pool[np.concatenate([chosen, extra])]
    return poses, np.arange(len(poses)) >= settings.poses


def uncalibrated(problem: Problem) -> Problem:
    """``problem`` with its robot's calibration set aside: goals and readings raw."""
    robot = dataclasses.replace(problem.robot, calibration=IDEAL, calibration_record={})
    return dataclasses.replace(problem, robot=robot)


def logged_readings_raw(table: pd.DataFrame, header: dict[str, Any]) -> pd.DataFrame:
    """A log's rows with its measured positions as the encoders read them: a run through
    a ``[calibration]`` logs the model's joint coordinates (its header's backend says
    which), which go back through it."""
    calibration = header.get("backend", {}).get("calibration_deg")
    if not calibration:
        return table
    g = Geometry.from_vector(np.radians([calibration[name] for name in PARAMETERS]))
    columns = ["position_theta1_rad", "position_theta2_rad"]
    positions = table[columns].to_numpy(dtype=float)
    finite = np.all(np.isfinite(positions), axis=1)
    raw = table.copy()
    raw.loc[finite, columns] = geometry.encoder_readings(positions[finite], g)
    return raw


def log_dwells(table: pd.DataFrame, windows_s: list[list[float]]) -> tuple[np.ndarray, np.ndarray]:
    """Each averaging window's mean measured position (n, 2), rad, and its time on the
    log's clock (n, 2), s, from a log's plan-phase rows whose ``plan_time_s`` falls in it
    (s of the plan)."""
    plan = table[table["phase"] == "plan"]
    plan_times = plan["plan_time_s"].to_numpy(dtype=float)
    times = plan["time_s"].to_numpy(dtype=float)
    positions = plan[["position_theta1_rad", "position_theta2_rad"]].to_numpy(dtype=float)
    readings, spans = [], []
    for index, (start, end) in enumerate(windows_s):
        inside = (plan_times >= start) & (plan_times <= end)
        measured = inside & np.all(np.isfinite(positions), axis=1)
        if not measured.any():
            raise InputError(
                f"calibration log: no measured sample in pose {index + 1}'s dwell "
                f"({start:.2f}-{end:.2f} s of the plan); did the run complete?"
            )
        readings.append(positions[measured].mean(axis=0))
        spans.append([times[inside].min(), times[inside].max()])
    return np.asarray(readings), np.asarray(spans)


def log_marker_path(table: pd.DataFrame, marker_distance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The marker's path as the log's readings put it, by the ideal kinematics: times (k,),
    s, and positions (k, 3), m, in the robot's frame (samples without a reading left out)."""
    positions = table[["position_theta1_rad", "position_theta2_rad"]].to_numpy(dtype=float)
    read = np.all(np.isfinite(positions), axis=1)
    times = table["time_s"].to_numpy(dtype=float)[read]
    return times, kinematics.forward_kinematics(positions[read], marker_distance_m)


def measurements(
    table: pd.DataFrame,
    plan: dict[str, Any],
    track: MarkerTrack,
    marker_distance_m: float,
    source: str,
) -> tuple[PoseMeasurements, PoseMeasurements]:
    """The fitted and the held-out poses' readings and marker positions, from a log's rows
    and its plan's ``calibration`` metadata and a tracker's track (named ``source``) of a
    marker at about ``marker_distance_m``, m."""
    readings, spans = log_dwells(table, plan["windows_s"])
    log_times, log_marker = log_marker_path(table, marker_distance_m)
    markers = dwell_means(track, log_times, log_marker, spans, source).means_m
    out = np.asarray(plan["held_out"], dtype=bool)
    return (
        PoseMeasurements(readings[~out], markers[~out]),
        PoseMeasurements(readings[out], markers[out]),
    )


@dataclass(frozen=True)
class Calibration:
    """A fit, its held-out judgement and what it was made from."""

    result: CalibrationFit
    held_out: HeldOut
    fitted: PoseMeasurements
    tested: PoseMeasurements
    tracker: str
    data_sha256: str

    def record(self) -> dict[str, Any]:
        """The robot file's ``[calibration]`` provenance (mm, deg)."""
        errors = {
            name: math.degrees(float(e))
            for name, e in zip(PARAMETERS, self.result.geometry_standard_errors, strict=True)
            if np.isfinite(e)
        }
        return {
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "data_sha256": self.data_sha256,
            "tracker": self.tracker,
            "method": "Levenberg-Marquardt on marker positions, registration jointly",
            "marker_distance_mm": self.result.marker_distance_m / MM,
            "poses": len(self.fitted.readings_rad),
            "held_out_poses": len(self.tested.readings_rad),
            "residual_rms_mm": self.result.residual_rms_m / MM,
            "held_out_rms_mm": self.held_out.rms_m / MM,
            "held_out_max_mm": float(np.max(self.held_out.errors_m, initial=0.0)) / MM,
            "predicted_tre_mm": float(np.sqrt(np.mean(self.held_out.predicted_tre_m**2))) / MM,
            "condition_number": self.result.observability.condition_number,
            "standard_error_deg": errors,
            "unidentified": list(self.result.observability.unidentified),
        }

    def calibrated(self, robot: Robot) -> Robot:
        """``robot`` with this calibration, and built as it says: a simulated robot made
        from the file (the pre-flight's prediction, a run without ``--plant-robot``) has
        the encoder zeros and the mechanism the calibration found."""
        found = self.result.geometry
        return dataclasses.replace(
            robot,
            encoder_offset=found.encoder_zero,
            mechanism=found.mechanism,
            calibration=found,
            calibration_record=self.record(),
        )


def calibrate(
    fitted: PoseMeasurements,
    tested: PoseMeasurements,
    marker_distance_m: float,
    tracker: str,
    data: bytes,
) -> Calibration:
    """Fit ``fitted`` from the marker's nominal distance, m, judge it on ``tested``;
    ``tracker`` names the measurement, ``data`` its bytes (hashed into the record)."""
    result = fit(fitted, marker_distance_m)
    judged = held_out(result, fitted, tested) if len(tested.readings_rad) else None
    if judged is None:
        raise InputError("calibration: no held-out pose; at least 1 is needed to judge the fit")
    return Calibration(result, judged, fitted, tested, tracker, hashlib.sha256(data).hexdigest())


def parameter_rows(calibration: Calibration) -> list[dict[str, Any]]:
    """One row per unknown: its name, value and standard error (deg for angles, mm for
    lengths, the Cayley vector as is) and whether the fit estimated it."""
    result = calibration.result
    rows = []
    for index, name in enumerate(UNKNOWNS):
        value, error = float(result.unknowns[index]), float(result.standard_errors[index])
        unit, scale = ("", 1.0) if name.startswith("rotation") else ("mm", 1 / MM)
        if name in PARAMETERS:
            unit, scale = "deg", math.degrees(1.0)
        rows.append(
            {
                "name": name,
                "value": value * scale,
                "standard_error": error * scale,
                "unit": unit,
                "identified": bool(np.isfinite(error)),
            }
        )
    return rows
