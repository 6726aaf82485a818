"""A run's log compared with its plan and the model: torques, joint paths, the platform's
path seen by motion capture, the executed cut, and the operator's holds.

The hardware verification's comparisons as data (:mod:`spm_opt.studies.hardware` describes
each).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from spm_opt.base.errors import InputError
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import MM
from spm_opt.model.rigid import Registration
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.executed_cut import tracking_error
from spm_opt.verify.motion_capture import (
    Capture,
    PathDeviation,
    path_deviation,
    reference_landmarks,
    rigid_registration,
    synthetic_capture,
    to_manipulator_frame,
)

SMOOTHING_S = 0.25
"""Window of the moving average shown beside the raw measured torque, s."""

CUT_SAMPLING_HZ = 10_000.0
"""Sampling of the plan's cut the executed cut is measured against, per s of plan time
(on the hardware run's plan, points at most 1.1 µm apart)."""

PACE_COLUMNS = ("plan_time_s", "feed", "feed_target")
"""The log's columns that say where along the plan each plan-phase row was."""


@dataclass(frozen=True)
class RunSamples:
    """The plan phase of a run: where along the plan each sample was and what was measured.

    Attributes
    ----------
    start_s : float, s
        When the plan phase began, on the log's clock.
    t : ndarray, shape (N,), s
        Run time: since the plan phase began (the figures' time axis).
    feed, feed_target : ndarray, shape (N,)
        The pace r = dτ/dt (1: as planned, 0: held) and the pace it was heading for.
    planned_q, planned_qd, planned_qdd : ndarray, shape (N, 2), SI
        What was commanded: q(τ), q′(τ) r and q″(τ) r² + q′(τ) ṙ at the logged plan time τ.
    measured_q : ndarray, shape (N, 2), rad
    measured_torque : ndarray, shape (N, 2), N·m (from the actuators' current)
    """

    start_s: float
    t: np.ndarray
    feed: np.ndarray
    feed_target: np.ndarray
    planned_q: np.ndarray
    planned_qd: np.ndarray
    planned_qdd: np.ndarray
    measured_q: np.ndarray
    measured_torque: np.ndarray

    @classmethod
    def from_log(cls, trajectory: Trajectory, log: pd.DataFrame) -> RunSamples:
        """The samples of the log's plan phase (rows whose read failed are left out), with
        the plan taken at each row's logged plan time and feed; ṙ is estimated from the
        logged feed by central differences over the plan phase."""
        plan = log[log["phase"] == "plan"]
        missing = [c for c in PACE_COLUMNS if c not in plan or plan[c].isna().any()]
        if missing:
            raise InputError(
                f"log: its plan phase has no {', '.join(missing)} (a log from before the "
                "feed override?)"
            )
        if plan["position_theta1_rad"].notna().sum() < 2:
            raise InputError("log: fewer than 2 measured samples in its plan phase")
        time_s = plan["time_s"].to_numpy()
        feed_rate = np.gradient(plan["feed"].to_numpy(), time_s)[:, None]
        kept = plan["position_theta1_rad"].notna().to_numpy()
        plan, feed_rate = plan[kept], feed_rate[kept]
        tau = plan["plan_time_s"].to_numpy() + trajectory.start_time
        feed = plan["feed"].to_numpy()
        velocity = trajectory.velocity(tau)
        return cls(
            start_s=float(time_s[0]),
            t=plan["time_s"].to_numpy() - time_s[0],
            feed=feed,
            feed_target=plan["feed_target"].to_numpy(),
            planned_q=trajectory.position(tau),
            planned_qd=velocity * feed[:, None],
            planned_qdd=trajectory.acceleration(tau) * feed[:, None] ** 2 + velocity * feed_rate,
            measured_q=plan[["position_theta1_rad", "position_theta2_rad"]].to_numpy(),
            measured_torque=plan[["torque_theta1_nm", "torque_theta2_nm"]].to_numpy(),
        )

    @property
    def feed_changed(self) -> bool:
        """The run had a hold or an override: its feed or target left 1 somewhere."""
        return bool(np.any(self.feed != 1.0) or np.any(self.feed_target != 1.0))

    def held_intervals(self) -> list[tuple[float, float]]:
        """Each stretch of run time (s) the feed was 0: from its first sample at 0 to the
        first sample after it above 0 (or the last sample)."""
        edges = np.diff(np.concatenate(([0], (self.feed <= 0.0).astype(int), [0])))
        begins, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        last = len(self.t) - 1
        return [
            (float(self.t[begin]), float(self.t[min(end, last)]))
            for begin, end in zip(begins, ends, strict=True)
        ]


@dataclass(frozen=True)
class TorqueComparison:
    """Model against measured torques per actuator, N·m."""

    model_rms_nm: list[float]
    measured_rms_nm: list[float]
    difference_rms_nm: list[float]
    smoothed_difference_rms_nm: list[float]


@dataclass(frozen=True)
class TrackingComparison:
    """Planned against measured joint angles per joint, deg."""

    max_error_deg: list[float]
    rms_error_deg: list[float]


@dataclass(frozen=True)
class MotionCaptureComparison:
    """The registration and the marker path's deviation from the planned path."""

    registration_rms_mm: float
    noise_std_mm: float
    deviation: PathDeviation


def model_torque(problem: Problem, samples: RunSamples) -> np.ndarray:
    """The model's actuator torques (N, 2), N·m, along the planned motion."""
    return dynamics.actuator_torque(
        problem.robot, samples.planned_q, samples.planned_qd, samples.planned_qdd
    )


def smoothed(values: np.ndarray, t: np.ndarray, window_s: float = SMOOTHING_S) -> np.ndarray:
    """Centred moving average (N, k) over ``window_s`` of samples at times t (N,), s."""
    period = float(np.median(np.diff(t)))
    width = max(1, int(round(window_s / period)))
    frame = pd.DataFrame(values)
    return frame.rolling(width, center=True, min_periods=1).mean().to_numpy()


def _rms(values: np.ndarray) -> list[float]:
    return np.sqrt(np.mean(values**2, axis=0)).tolist()


def compare_torques(problem: Problem, samples: RunSamples) -> TorqueComparison:
    """Figs. 19–20 in numbers: RMS of the model, the measurement and their difference."""
    model = model_torque(problem, samples)
    measured = samples.measured_torque
    return TorqueComparison(
        model_rms_nm=_rms(model),
        measured_rms_nm=_rms(measured),
        difference_rms_nm=_rms(measured - model),
        smoothed_difference_rms_nm=_rms(smoothed(measured, samples.t) - model),
    )


def compare_tracking(samples: RunSamples) -> TrackingComparison:
    """How far the measured joints were from the plan, deg."""
    return TrackingComparison(*tracking_error(samples.measured_q, samples.planned_q))


def capture_run(problem: Problem, samples: RunSamples, seed: int = 0) -> tuple[Capture, np.ndarray]:
    """A synthetic capture of the run (landmarks and marker in the camera frame) and the
    reference landmarks in the manipulator frame, (8, 3), m."""
    landmarks = reference_landmarks(problem.robot)
    marker = kinematics.forward_kinematics(samples.measured_q, problem.robot.upper_platform_radius)
    return synthetic_capture(landmarks, samples.t, marker, rng=seed), landmarks


def compare_motion_capture(
    problem: Problem,
    samples: RunSamples,
    capture: Capture,
    landmarks_m: np.ndarray,
) -> tuple[MotionCaptureComparison, Registration, np.ndarray]:
    """Register the capture, bring the marker into the manipulator frame and measure its
    deviation from the planned platform path. Returns the comparison, the registration and
    the tracked path in M, (N, 3), m."""
    registration = rigid_registration(capture.landmarks_c, landmarks_m)
    tracked = to_manipulator_frame(registration, capture.marker_c)
    desired = kinematics.forward_kinematics(samples.planned_q, problem.robot.upper_platform_radius)
    comparison = MotionCaptureComparison(
        registration_rms_mm=registration.rms_mm,
        noise_std_mm=capture.noise_std_m / MM,
        deviation=path_deviation(tracked, desired),
    )
    return comparison, registration, tracked


@dataclass(frozen=True)
class Hold:
    """One hold the operator asked for, from the header's feed events; times in run time
    (s since the plan phase began), durations from the request, s (None: never reached).

    Attributes
    ----------
    asked_s : float, s
    plan_time_s : float or None, s
        The plan's time (since its start) where the feed reached 0.
    to_held_s, to_rest_s : float or None, s
        From the request to the feed at 0, and to rest confirmed.
    lasted_s : float, s
        From the request to the resume, or to the end of the log.
    resumed : bool
    """

    asked_s: float
    plan_time_s: float | None
    to_held_s: float | None
    to_rest_s: float | None
    lasted_s: float
    resumed: bool


def holds_from_events(events: list[dict[str, Any]], start_s: float, end_s: float) -> list[Hold]:
    """The holds among a run's feed events (the header's ``feed_events``): each from its
    "hold" to its "resume"; ``start_s`` and ``end_s`` are the plan phase's start and the
    log's end on the log's clock, s. A feed set to 0 by an override is no hold."""
    holds, current = [], None
    for event in events:
        name, at = event["event"], event["time_s"] - start_s
        if name == "hold":
            current = {"asked_s": at, "plan_time_s": None, "to_held_s": None, "to_rest_s": None}
        elif current is not None and name == "held":
            current.update(plan_time_s=event["plan_time_s"], to_held_s=at - current["asked_s"])
        elif current is not None and name == "at rest":
            current["to_rest_s"] = at - current["asked_s"]
        elif current is not None and name == "resume":
            holds.append(Hold(**current, lasted_s=at - current["asked_s"], resumed=True))
            current = None
    if current is not None:
        lasted = end_s - start_s - current["asked_s"]
        holds.append(Hold(**current, lasted_s=lasted, resumed=False))
    return holds


def override_count(events: list[dict[str, Any]]) -> int:
    """How many times the operator changed the feed override ("feed 50%" events)."""
    return sum(event["event"].startswith("feed ") for event in events)


@dataclass(frozen=True)
class CutComparison:
    """The executed cut against the plan's, on the skull.

    Attributes
    ----------
    planned_m : ndarray, shape (M, 3), m
        The plan's cut, sampled at :data:`CUT_SAMPLING_HZ` of plan time.
    executed_m : ndarray, shape (N, 3), m
        The cut at the measured joint angles.
    distance_m : ndarray, shape (N,), m
        Each executed point's distance from the nearest sample of the plan's cut.
    """

    planned_m: np.ndarray
    executed_m: np.ndarray
    distance_m: np.ndarray

    @property
    def max_distance_mm(self) -> float:
        """The executed cut's largest distance from the plan's cut, mm."""
        return float(np.max(self.distance_m)) / MM


def compare_cut(problem: Problem, trajectory: Trajectory, samples: RunSamples) -> CutComparison:
    """The cut at the measured joint angles against the plan's cut, sampled finely."""
    t = np.arange(trajectory.start_time, trajectory.end_time, 1.0 / CUT_SAMPLING_HZ)
    planned = trajectory.cut_points(problem.contour, np.append(t, trajectory.end_time))
    directions = kinematics.forward_kinematics(samples.measured_q, 1.0)
    executed = problem.contour.cut_points(directions)
    return CutComparison(planned, executed, cKDTree(planned).query(executed)[0])


def feed_summary(holds: list[Hold], overrides: int, cut: CutComparison) -> dict[str, Any]:
    """The holds, the number of overrides and the executed cut's deviation, as plain data."""
    return {
        "holds": {"overrides": overrides, "each": [asdict(hold) for hold in holds]},
        "executed_cut": {"max_distance_mm": cut.max_distance_mm},
    }


def verification_summary(
    torques: TorqueComparison, tracking: TrackingComparison, capture: MotionCaptureComparison
) -> dict[str, Any]:
    """The three comparisons as plain data."""
    return {
        "torques": asdict(torques),
        "tracking": asdict(tracking),
        "motion_capture": {
            "registration_rms_mm": capture.registration_rms_mm,
            "noise_std_mm": capture.noise_std_mm,
            **capture.deviation.to_dict(),
        },
    }
