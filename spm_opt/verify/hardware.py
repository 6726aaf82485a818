"""The paper's hardware verification (Section 6), from an execution log.

Three comparisons, as in the paper:

- torques: the model's actuator torques along the plan against the torques the actuators'
  current gives through the current map (Figs. 19–20), with the RMS of their difference;
  the measured torque is also shown smoothed (a centred moving average), because Present
  Current is quantised in 16.11 mA steps, about 0.12 N·m at the output, the size of the
  torques themselves;
- joint paths: planned against measured (Fig. 15);
- the platform's path seen by motion capture (Figs. 25–26): the marker at the platform's
  centre, tracked in the camera frame, is brought into the manipulator frame through the
  rigid registration of 8 reference landmarks and compared with the planned path (the
  paper's centroid distance, and RMS and maximum closest-point distances). Without cameras
  the capture is synthetic: the measured joint path through the forward kinematics, seen
  from an unknown rigid transform with 0.3–0.6 mm noise.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from spm_opt.errors import InputError
from spm_opt.execution.log import read_log
from spm_opt.files import write_atomically
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.plots import to_png
from spm_opt.problem import Problem
from spm_opt.report.markdown import markdown_table
from spm_opt.trajectory import Trajectory
from spm_opt.verify.motion_capture import (
    Capture,
    PathDeviation,
    Registration,
    path_deviation,
    reference_landmarks,
    rigid_registration,
    synthetic_capture,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

SMOOTHING_S = 0.25
"""Window of the moving average shown beside the raw measured torque, s."""


@dataclass(frozen=True)
class RunSamples:
    """The plan phase of a run: times since the plan's start and what was measured.

    Attributes
    ----------
    t : ndarray, shape (N,), s
    planned_q, planned_qd, planned_qdd : ndarray, shape (N, 2), SI
    measured_q : ndarray, shape (N, 2), rad
    measured_torque : ndarray, shape (N, 2), N·m (from the actuators' current)
    """

    t: np.ndarray
    planned_q: np.ndarray
    planned_qd: np.ndarray
    planned_qdd: np.ndarray
    measured_q: np.ndarray
    measured_torque: np.ndarray

    @classmethod
    def from_log(cls, trajectory: Trajectory, log: pd.DataFrame) -> RunSamples:
        """The samples of the log's plan phase (rows whose read failed are left out)."""
        plan = log[log["phase"] == "plan"]
        start = plan["time_s"].iloc[0] if len(plan) else 0.0
        plan = plan[plan["time_s"] - start <= trajectory.duration + 1e-9]
        plan = plan.dropna(subset=["position_theta1_rad"])
        if len(plan) < 2:
            raise InputError("log: fewer than 2 measured samples in its plan phase")
        t = np.minimum(plan["time_s"].to_numpy() - start, trajectory.duration)
        t = t + trajectory.start_time
        measured_q = plan[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
        torque = plan[["torque_theta1_nm", "torque_theta2_nm"]].to_numpy()
        return cls(
            t=t,
            planned_q=trajectory.position(t),
            planned_qd=trajectory.velocity(t),
            planned_qdd=trajectory.acceleration(t),
            measured_q=measured_q,
            measured_torque=torque,
        )


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
    error = (samples.measured_q - samples.planned_q) / DEG
    return TrackingComparison(np.max(np.abs(error), axis=0).tolist(), _rms(error))


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
    tracked = registration.apply(capture.marker_c)
    desired = kinematics.forward_kinematics(samples.planned_q, problem.robot.upper_platform_radius)
    comparison = MotionCaptureComparison(
        registration_rms_mm=registration.rms_error_m / MM,
        noise_std_mm=capture.noise_std_m / MM,
        deviation=path_deviation(tracked, desired),
    )
    return comparison, registration, tracked


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


# ---------------------------------------------------------------------- figures
def torque_figure(problem: Problem, samples: RunSamples, joint: int) -> Figure:
    """One actuator's model and measured torques over time (the paper's Fig. 19 or 20)."""
    from matplotlib.figure import Figure

    model = model_torque(problem, samples)[:, joint]
    measured = samples.measured_torque[:, joint]
    figure = Figure(figsize=(8, 4), layout="constrained")
    axis = figure.subplots()
    axis.plot(samples.t, measured, color="0.7", linewidth=0.8, label="measured (from current)")
    axis.plot(
        samples.t,
        smoothed(samples.measured_torque, samples.t)[:, joint],
        color="tab:orange",
        label=f"measured, {SMOOTHING_S:g} s moving average",
    )
    axis.plot(samples.t, model, color="tab:blue", label="model (Lagrange, friction)")
    rms = float(np.sqrt(np.mean((measured - model) ** 2)))
    axis.set_title(f"actuator {joint + 1}: torque, RMS difference {rms:.3f} N·m")
    axis.set_xlabel("time (s)")
    axis.set_ylabel("torque (N·m)")
    axis.grid(True, alpha=0.3)
    axis.legend(loc="best")
    return figure


def tracking_figure(samples: RunSamples) -> Figure:
    """Planned and measured joint angles, and their difference (the paper's Fig. 15)."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8, 6), layout="constrained")
    angles, errors = figure.subplots(2, 1, sharex=True)
    for joint, colour in enumerate(("tab:blue", "tab:orange")):
        angles.plot(
            samples.t, samples.planned_q[:, joint] / DEG, color=colour, label=f"θ{joint + 1} plan"
        )
        angles.plot(
            samples.t,
            samples.measured_q[:, joint] / DEG,
            color=colour,
            linestyle="--",
            label=f"θ{joint + 1} measured",
        )
        errors.plot(
            samples.t,
            (samples.measured_q[:, joint] - samples.planned_q[:, joint]) / DEG,
            color=colour,
            label=f"θ{joint + 1}",
        )
    angles.set_ylabel("joint angle (deg)")
    errors.set_ylabel("measured − plan (deg)")
    errors.set_xlabel("time (s)")
    for axis in (angles, errors):
        axis.grid(True, alpha=0.3)
        axis.legend(loc="best")
    return figure


def capture_figure(
    samples: RunSamples,
    problem: Problem,
    tracked_m: np.ndarray,
    comparison: MotionCaptureComparison,
) -> Figure:
    """Desired and tracked platform paths seen from above, with their centroids (the
    paper's Figs. 25–26)."""
    from matplotlib.figure import Figure

    desired = kinematics.forward_kinematics(samples.planned_q, problem.robot.upper_platform_radius)
    figure = Figure(figsize=(7, 6), layout="constrained")
    axis = figure.subplots()
    axis.plot(desired[:, 0] / MM, desired[:, 1] / MM, color="tab:blue", label="desired")
    axis.plot(
        tracked_m[:, 0] / MM,
        tracked_m[:, 1] / MM,
        color="tab:red",
        linewidth=0.6,
        alpha=0.7,
        label="tracked (motion capture, registered)",
    )
    for points, colour, name in (
        (desired, "tab:blue", "desired"),
        (tracked_m, "tab:red", "tracked"),
    ):
        centre = points.mean(axis=0) / MM
        axis.plot(*centre[:2], marker="x", markersize=10, color=colour, label=f"centroid, {name}")
    d = comparison.deviation
    axis.set_title(
        f"platform path: centroids {d.centroid_distance_mm:.3f} mm apart, RMS "
        f"{d.rms_distance_mm:.3f} mm, max {d.max_distance_mm:.3f} mm "
        f"(registration RMS {comparison.registration_rms_mm:.3f} mm)",
        fontsize=9,
    )
    axis.set_xlabel("x (mm)")
    axis.set_ylabel("y (mm)")
    axis.set_aspect("equal")
    axis.grid(True, alpha=0.3)
    axis.legend(loc="best", fontsize=8)
    return figure


def write_verification(
    problem: Problem, trajectory: Trajectory, log_path: Path, out: Path, seed: int = 0
) -> list[Path]:
    """Analyse a run's log and write the report and figures into ``out`` (all or none).

    Files: ``hardware_verification.md`` and ``.json`` (the three comparisons),
    ``fig15_tracking.png``, ``fig19_torque_theta1.png``, ``fig20_torque_theta2.png``,
    ``fig25_motion_capture.png``.
    """
    log, header = read_log(log_path)
    samples = RunSamples.from_log(trajectory, log)
    capture, landmarks = capture_run(problem, samples, seed)
    mocap, _, tracked = compare_motion_capture(problem, samples, capture, landmarks)
    summary = verification_summary(
        compare_torques(problem, samples), compare_tracking(samples), mocap
    )
    summary["run"] = {key: header.get(key) for key in ("completed", "reason", "samples", "loop")}
    backend = header.get("backend", {})
    summary["run"]["backend"] = backend.get("backend")
    summary["run"]["plant_robot"] = backend.get("plant_robot")  # the simulated robot's
    files = {
        out / "hardware_verification.json": json.dumps(summary, indent=2) + "\n",
        out / "hardware_verification.md": _markdown(problem, summary),
        out / "fig15_tracking.png": to_png(tracking_figure(samples)),
        out / "fig19_torque_theta1.png": to_png(torque_figure(problem, samples, 0)),
        out / "fig20_torque_theta2.png": to_png(torque_figure(problem, samples, 1)),
        out / "fig25_motion_capture.png": to_png(capture_figure(samples, problem, tracked, mocap)),
    }
    write_atomically(files)
    return list(files)


def _markdown(problem: Problem, summary: dict[str, Any]) -> str:
    run, torques, tracking = summary["run"], summary["torques"], summary["tracking"]
    mocap = summary["motion_capture"]
    loop = run.get("loop") or {}
    lines = [
        f"# Hardware verification: {problem.name}",
        "",
        f"Backend: {run.get('backend')}"
        + (f" (plant: {run['plant_robot']})" if run.get("plant_robot") else "")
        + "; "
        + ("run completed" if run.get("completed") else f"safe stop: {run.get('reason')}")
        + f"; {run.get('samples')} samples at "
        f"{loop.get('achieved_rate_hz', float('nan')):.1f} Hz, period error p99 "
        f"{loop.get('period_error_p99_ms', float('nan')):.3f} ms.",
        "",
    ]
    rows = [
        ("model torque RMS, N·m", torques["model_rms_nm"]),
        ("measured torque RMS, N·m", torques["measured_rms_nm"]),
        ("RMS difference, N·m", torques["difference_rms_nm"]),
        (f"RMS difference, smoothed {SMOOTHING_S:g} s, N·m", torques["smoothed_difference_rms_nm"]),
        ("max tracking error, deg", tracking["max_error_deg"]),
        ("RMS tracking error, deg", tracking["rms_error_deg"]),
    ]
    lines += markdown_table(
        ["figure", "θ1", "θ2"], [[name, f"{a:.4f}", f"{b:.4f}"] for name, (a, b) in rows]
    )
    lines += [
        "",
        "Motion capture (synthetic: unknown rigid transform, noise "
        f"{mocap['noise_std_mm']:.3f} mm): registration RMS {mocap['registration_rms_mm']:.3f} mm "
        "(the paper: 0.587 mm); centroid distance "
        f"{mocap['centroid_distance_mm']:.3f} mm (the paper: 0.731 mm); closest-point distance "
        f"RMS {mocap['rms_distance_mm']:.3f} mm, max {mocap['max_distance_mm']:.3f} mm.",
        "",
    ]
    return "\n".join(lines)
