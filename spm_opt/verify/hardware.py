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

A run the operator held or overrode (the feed) is compared at what was commanded: the plan
at each row's logged plan time and feed, against run time since the plan phase began; the
figures shade the holds, and the report lists them from the header's feed events. The
executed cut (the measured joints on the skull) is compared with the plan's cut, and
judged by the problem's rules as a plan is (:mod:`spm_opt.evaluate_execution`): the
measured cut, and, given the plant's true state (a simulated robot's or the emulator's
trace), the true cut.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from spm_opt.errors import InputError
from spm_opt.evaluate_execution import LogReports, evaluate_log, tracking_error
from spm_opt.execution.log import read_log
from spm_opt.figure_rules import mark_top_view
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
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

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
    tracked = registration.apply(capture.marker_c)
    desired = kinematics.forward_kinematics(samples.planned_q, problem.robot.upper_platform_radius)
    comparison = MotionCaptureComparison(
        registration_rms_mm=registration.rms_error_m / MM,
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


# ---------------------------------------------------------------------- figures
def shade_holds(axis: Axes, samples: RunSamples) -> None:
    """Shade each stretch of run time the feed was 0, labelled once "feed hold"."""
    for k, (begin, end) in enumerate(samples.held_intervals()):
        label = "feed hold" if k == 0 else "_nolegend_"
        axis.axvspan(begin, end, color="0.88", zorder=0, label=label)


def torque_figure(problem: Problem, samples: RunSamples, joint: int) -> Figure:
    """One actuator's model and measured torques over run time (the paper's Fig. 19 or
    20), holds shaded."""
    from matplotlib.figure import Figure

    model = model_torque(problem, samples)[:, joint]
    measured = samples.measured_torque[:, joint]
    figure = Figure(figsize=(8, 4.6), layout="constrained")
    axis = figure.subplots()
    shade_holds(axis, samples)
    axis.plot(samples.t, measured, color="0.6", linewidth=0.8, label="measured (from current)")
    axis.plot(
        samples.t,
        smoothed(samples.measured_torque, samples.t)[:, joint],
        color="tab:orange",
        label=f"measured, {SMOOTHING_S:g} s moving average",
    )
    axis.plot(samples.t, model, color="tab:blue", label="model (Lagrange, friction)")
    rms = float(np.sqrt(np.mean((measured - model) ** 2)))
    axis.set_title(f"actuator {joint + 1}: torque, RMS difference {rms:.3f} N·m")
    axis.set_xlabel("run time (s)")
    axis.set_ylabel("torque (N·m)")
    axis.grid(True, alpha=0.3)
    figure.legend(*axis.get_legend_handles_labels(), loc="outside lower center", ncol=2)
    return figure


def tracking_figure(samples: RunSamples) -> Figure:
    """Planned and measured joint angles and their difference over run time (the paper's
    Fig. 15), holds shaded; below them the feed and its target if it ever left 1."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8, 7.5 if samples.feed_changed else 6), layout="constrained")
    ratios = (3, 3, 1.5) if samples.feed_changed else (1, 1)
    axes = figure.subplots(len(ratios), 1, sharex=True, height_ratios=ratios)
    angles, errors = axes[:2]
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
    if samples.feed_changed:
        _feed_panel(axes[2], samples)
    axes[-1].set_xlabel("run time (s)")
    for axis in axes:
        shade_holds(axis, samples)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    figure.suptitle("Joint angles, planned (at the logged plan time) and measured (Fig. 15)")
    return figure


def _feed_panel(axis: Axes, samples: RunSamples) -> None:
    axis.plot(samples.t, samples.feed, color="k", label="feed")
    axis.plot(samples.t, samples.feed_target, color="tab:red", linestyle="--", label="target")
    axis.set_ylabel("feed (-)")
    axis.set_ylim(-0.05, max(1.0, float(np.max(samples.feed_target))) + 0.1)


def cut_figure(samples: RunSamples, cut: CutComparison, holds: list[Hold]) -> Figure:
    """Left: the executed cut and the plan's seen from above (x, y, mm). Right: the executed
    cut's distance from the plan's cut (mm) along the plan's cut (mm), where the two,
    which coincide at the scale of the cut, stand apart. Both with a numbered marker where
    each hold's feed reached 0."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(12, 5.5), layout="constrained")
    top, off = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.4]})
    planned, executed = cut.planned_m / MM, cut.executed_m / MM
    along, distance = _along_plan(samples, cut), cut.distance_m / MM
    top.plot(planned[:, 0], planned[:, 1], color="tab:blue", linewidth=2.0, label="plan")
    top.plot(executed[:, 0], executed[:, 1], color="tab:red", linewidth=0.7, label="executed")
    off.plot(along, distance, color="tab:red", linewidth=0.7)
    stops = [(number, int(np.argmin(np.abs(samples.t - at)))) for number, at in _stops(holds)]
    _mark_stops(top, executed[:, :2], stops, "hold: feed at 0")
    _mark_stops(off, np.column_stack([along, distance]), stops)
    top.set_title("seen from above", fontsize=10)
    top.set_xlabel("x (mm)")
    top.set_ylabel("y (mm)")
    top.set_aspect("equal")
    mark_top_view(top)
    off.set_title("the executed cut's distance from the plan's cut", fontsize=10)
    off.set_xlabel("distance along the plan's cut (mm)")
    off.set_ylabel("distance from the plan's cut (mm)")
    for axis in (top, off):
        axis.grid(True, alpha=0.3)
    figure.legend(*top.get_legend_handles_labels(), loc="outside lower center", ncol=3)
    figure.suptitle(f"Executed cut against the plan: largest distance {cut.max_distance_mm:.3f} mm")
    return figure


def _mark_stops(
    axis: Axes, points: np.ndarray, stops: list[tuple[int, int]], label: str = "_nolegend_"
) -> None:
    """A numbered white marker at ``points[index]`` (N, 2) for each (number, index) of
    ``stops``, the first labelled ``label``."""
    for k, (number, index) in enumerate(stops):
        point = tuple(points[index])
        shown = label if k == 0 else "_nolegend_"
        axis.plot(*point, "o", color="k", markerfacecolor="white", label=shown)
        axis.annotate(str(number), point, xytext=(4, 4), textcoords="offset points")


def _stops(holds: list[Hold]) -> list[tuple[int, float]]:
    """(number from 1, run time in s) of each hold whose feed reached 0."""
    return [
        (number, hold.asked_s + hold.to_held_s)
        for number, hold in enumerate(holds, start=1)
        if hold.to_held_s is not None
    ]


def _along_plan(samples: RunSamples, cut: CutComparison) -> np.ndarray:
    """How far along the plan's cut (N,), mm, each sample's commanded point lies: the
    length of the plan's cut through the points commanded up to it (at the planned angles,
    on the skull radius of the plan's nearest point), still while the feed is held."""
    planned = cut.planned_m[::10]
    radius = np.linalg.norm(planned, axis=1)
    directions = kinematics.forward_kinematics(samples.planned_q, 1.0)
    nearest = cKDTree(planned / radius[:, None]).query(directions)[1]
    points = directions * radius[nearest, None]
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)]) / MM


def capture_figure(
    samples: RunSamples,
    problem: Problem,
    tracked_m: np.ndarray,
    comparison: MotionCaptureComparison,
) -> Figure:
    """Desired and tracked platform paths seen from above (x, y, mm), with their centroids
    (the paper's Figs. 25–26); the legend below the plot, clear of the centroids."""
    from matplotlib.figure import Figure

    desired = kinematics.forward_kinematics(samples.planned_q, problem.robot.upper_platform_radius)
    figure = Figure(figsize=(7, 6.5), layout="constrained")
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
    mark_top_view(axis)
    figure.legend(*axis.get_legend_handles_labels(), loc="outside lower center", ncol=2)
    return figure


def write_verification(
    problem: Problem,
    trajectory: Trajectory,
    log_path: Path,
    out: Path,
    seed: int = 0,
    trace_path: Path | None = None,
) -> list[Path]:
    """Analyse a run's log (and the plant's true state in ``trace_path``, if given) and
    write the report and figures into ``out`` (all or none).

    Files: ``hardware_verification.md`` and ``.json`` (the three comparisons, the holds
    and overrides, the executed cut's deviation and its judgement), ``fig15_tracking.png``,
    ``fig19_torque_theta1.png``, ``fig20_torque_theta2.png``, ``fig25_motion_capture.png``,
    ``executed_cut.png``.
    """
    judged = evaluate_log(problem, log_path, trace_path)
    log, header = read_log(log_path)
    samples = RunSamples.from_log(trajectory, log)
    capture, landmarks = capture_run(problem, samples, seed)
    mocap, _, tracked = compare_motion_capture(problem, samples, capture, landmarks)
    events = header.get("feed_events", [])
    holds = holds_from_events(events, samples.start_s, float(log["time_s"].iloc[-1]))
    cut = compare_cut(problem, trajectory, samples)
    summary = verification_summary(
        compare_torques(problem, samples), compare_tracking(samples), mocap
    )
    summary.update(feed_summary(holds, override_count(events), cut))
    summary["judged"] = {
        "measured": judged.measured.to_dict(),
        "true": None if judged.true is None else judged.true.to_dict(),
    }
    summary["run"] = {key: header.get(key) for key in ("completed", "reason", "samples", "loop")}
    backend = header.get("backend", {})
    summary["run"]["backend"] = backend.get("backend")
    summary["run"]["plant_robot"] = backend.get("plant_robot")  # the simulated robot's
    files = {
        out / "hardware_verification.json": json.dumps(summary, indent=2) + "\n",
        out / "hardware_verification.md": _markdown(problem, summary)
        + "\n"
        + _judged_markdown(judged),
        out / "fig15_tracking.png": to_png(tracking_figure(samples)),
        out / "fig19_torque_theta1.png": to_png(torque_figure(problem, samples, 0)),
        out / "fig20_torque_theta2.png": to_png(torque_figure(problem, samples, 1)),
        out / "fig25_motion_capture.png": to_png(capture_figure(samples, problem, tracked, mocap)),
        out / "executed_cut.png": to_png(cut_figure(samples, cut, holds)),
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
        "Executed cut (measured joint angles on the skull): largest distance from the plan's "
        f"cut {summary['executed_cut']['max_distance_mm']:.3f} mm.",
        "",
        *_holds_markdown(summary["holds"]),
    ]
    return "\n".join(lines)


def _holds_markdown(holds: dict[str, Any]) -> list[str]:
    lines = ["## Holds and overrides", ""]
    if not holds["each"] and not holds["overrides"]:
        return [*lines, "No holds or overrides.", ""]
    if holds["each"]:
        lines += [
            "Run time since the plan phase began; durations from the request, s.",
            "",
            *markdown_table(
                [
                    "hold",
                    "asked, s",
                    "stopped at plan time, s",
                    "to feed 0, s",
                    "to rest, s",
                    "lasted, s",
                ],
                [_hold_row(number, hold) for number, hold in enumerate(holds["each"], start=1)],
            ),
            "",
        ]
    return [*lines, f"Overrides: {holds['overrides']}.", ""]


def _hold_row(number: int, hold: dict[str, Any]) -> list[str]:
    def seconds(value: float | None) -> str:
        return "—" if value is None else f"{value:.3f}"

    lasted = seconds(hold["lasted_s"]) + ("" if hold["resumed"] else " (not resumed)")
    return [
        str(number),
        seconds(hold["asked_s"]),
        seconds(hold["plan_time_s"]),
        seconds(hold["to_held_s"]),
        seconds(hold["to_rest_s"]),
        lasted,
    ]


def _judged_markdown(judged: LogReports) -> str:
    """The executed cut judged by the problem's rules: the measured cut's figures beside
    the true cut's (when a trace was given), then each one's violations."""
    reports = {"measured": judged.measured, "true": judged.true}
    reports = {name: report for name, report in reports.items() if report is not None}

    def figure(name: str, value: Any) -> list[str]:
        return [name, *(_format_figure(getattr(r, value)) for r in reports.values())]

    rows = [
        figure("max contour deviation, mm", "max_contour_deviation_mm"),
        figure("RMS contour deviation, mm", "rms_contour_deviation_mm"),
        figure("max landmark error, mm", "max_landmark_error_mm"),
        figure("coverage gap, mm", "coverage_gap_mm"),
        figure("max backtrack, mm", "max_backtrack_mm"),
        figure("max tracking error θ1, θ2, deg", "max_tracking_error_deg"),
        figure("RMS tracking error θ1, θ2, deg", "rms_tracking_error_deg"),
    ]
    for k, visit in enumerate(judged.measured.landmark_errors_mm):
        errors = [f"{r.landmark_errors_mm[k]['error_mm']:.4f}" for r in reports.values()]
        rows.append([f"landmark {visit['landmark']} error, mm", *errors])
    rows.append(["violations", *(str(len(r.violations)) for r in reports.values())])
    lines = [
        "## The executed cut, judged",
        "",
        "By the problem's rules, as a plan is judged (`spm-opt evaluate PROBLEM LOG.csv`), "
        "from the plan's start to the log's end"
        + (
            "; the true cut is the plant's own angles, without the encoder offsets the "
            "measured ones carry."
            if judged.true is not None
            else "."
        ),
        "",
        *markdown_table(["figure", *(f"{name} cut" for name in reports)], rows),
        "",
    ]
    for name, report in reports.items():
        broken = [f"- {v}" for v in report.violations] or ["- none"]
        lines += [f"Violations of the {name} cut:", "", *broken, ""]
    return "\n".join(lines)


def _format_figure(value: Any) -> str:
    if isinstance(value, list):
        return ", ".join(f"{v:.4f}" for v in value)
    return f"{value:.4f}"
