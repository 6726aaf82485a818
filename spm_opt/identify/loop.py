"""Each actuator's position and velocity loop identified from execution logs: the goals
sent and the positions measured.

The loop model of :mod:`spm_opt.execution.tracking`, per joint: q̈ = ωv (Kp (g − q) − q̇),
Kp the position loop's gain (``position_loop_gain_per_s``, 1/s: position error to rate
command) and ωv the velocity loop's bandwidth (``velocity_loop_bandwidth_per_s``, 1/s: the
rate follows its command as a first-order lag). Each goal g_k is held over its control
period [t_k, t_k + T) and the position q_k is read at t_k, so the model's exact
discretisation (zero-order hold, ``scipy.signal.cont2discrete``) relates them one period
ahead:

    q_{k+1} + α1 q_k + α2 q_{k−1} = β1 g_k + β2 g_{k−1},

α and β functions of Kp, ωv and T. Each side divided by its sum (equal: at rest q = g),
the difference is the logged goal less the one the model needs for the measured positions
(as T → 0, g − q − q̇/Kp − q̈/(Kp ωv): the executor's lead), rad. Kp and ωv of each joint
minimise its sum of squares over every period of the logs, all phases
(``scipy.optimize.least_squares`` over their logarithms, from the prior's), goals and
positions both through the same zero-phase low-pass filter first (4th-order Butterworth
forward and back at :data:`CUTOFF_HZ`, which leaves the relation exact and takes out the
encoder's rounding, which the relation's second differences would amplify). A log is put
on a uniform grid of its median period, the goals held (a missed cycle holds its goal
twice) and the positions interpolated; rows without a position split it into runs. The
read's and the write's latency within a cycle count as part of the loop, as they do for
the executor's goals; a log of a loop that overran often is a poor one (the emulator on an
overloaded machine, 1647 of 11439 cycles late: ωv 670 and 960 1/s). Standard errors:
σ² (JᵀJ)⁻¹ times the residuals' correlation factor
(:func:`~spm_opt.identify.samples.correlation_factor` over one period of the cutoff).

From positions the model's own integration gives (``tests/test_identify_loop.py``), Kp
and ωv come out within 1e-5 and 4e-4 of the truth, at 100 and 500 Hz, within two
standard errors. On the simulated robot whose plant is ``prototype_plant.toml`` (position
P gain 32 1/s, a PI velocity loop on the joints' inertia, 1 ms steps), the 120 s
excitation of ``problems/identification.toml`` logged at 500 Hz gives Kp 32.92 and 32.73
1/s (± 0.015 and 0.009), ωv 96.5 and 94.3 1/s (± 1.7 and 0.9); at its old 4.5 rpm, Kp
32.88 and 32.72 and ωv 71 and 75. The plant is not the model: ωv depends on the motion
(velocity P gain over the joints' inertia at θ = 0: 87 and 116 1/s), by far more than its
standard error, which measures the noise and not the model's mismatch; Kp comes out 2–3 %
above the plant's 32 (a steady ramp lags as if it were 32.5: the plant's 1 ms step leads it
by half a step). Led by (32.92, 32.73; 96.5, 94.3) 1/s, a 30 s excitation of the same
problem run at 100 Hz on the plant tracked with an RMS error of 0.017° and 0.015°
(largest 0.114° and 0.100°) against 0.041° and 0.043° (0.124° and 0.126°) led by
prototype.toml's (32, 32; 134, 178). An output-error fit (the model's response simulated
from the goals alone, compared with the positions) gave (35.1, 35.0; 111, 107), which led
to 0.092° and 0.102°: it fits the whole response of a plant that is not the model, not the
goal that drives it along a reference.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.optimize
import scipy.signal

from spm_opt.base.errors import InputError
from spm_opt.base.markdown import markdown_table
from spm_opt.execution.log import read_execution_log
from spm_opt.identify.samples import (
    FILTER_ORDER,
    check_log_rows,
    correlation_factor,
    log_values,
    named,
)
from spm_opt.model.actuator import LOOP_RATE_RANGE_PER_S
from spm_opt.model.params import Robot

CUTOFF_HZ = 5.0
"""Cutoff of the zero-phase filter on goals and positions, Hz (at most a fifth of a log's
rate): above the plans' band; on the simulated robot's 120 s logs the estimates moved by
under 0.1 % (Kp) and up to 10 % (ωv) from 2 to 40 Hz."""
SIGNIFICANCE = 2.0
"""A joint's estimates replace the prior's when Kp and ωv are each at least this many
standard errors and lie in the range a robot file accepts
(:data:`~spm_opt.model.actuator.LOOP_RATE_RANGE_PER_S`)."""
MIN_RUN_PERIODS = 4
"""Shortest run used, in periods of the cutoff (one at each end is trimmed: the filter's
start and end)."""


@dataclass(frozen=True)
class LoopEstimate:
    """The loops' parameters per joint (θ1, θ2), estimated and prior.

    Attributes
    ----------
    gain_per_s, gain_error_per_s : ndarray, shape (2,)
        Kp and its standard error, 1/s.
    bandwidth_per_s, bandwidth_error_per_s : ndarray, shape (2,)
        ωv and its standard error, 1/s.
    prior_gain_per_s, prior_bandwidth_per_s : ndarray, shape (2,)
        The problem's robot's, 1/s.
    carried : ndarray of bool, shape (2,)
        Whether the estimate is significant (:data:`SIGNIFICANCE`); where not, the
        identified robot keeps the prior's.
    residual_rad : ndarray, shape (2,)
        RMS of the logged goals less the estimated loops' (filtered), rad.
    periods : int
        Control periods used.
    """

    gain_per_s: np.ndarray
    gain_error_per_s: np.ndarray
    bandwidth_per_s: np.ndarray
    bandwidth_error_per_s: np.ndarray
    prior_gain_per_s: np.ndarray
    prior_bandwidth_per_s: np.ndarray
    carried: np.ndarray
    residual_rad: np.ndarray
    periods: int

    def robot(self, robot: Robot) -> Robot:
        """``robot`` with each joint's loop parameters the estimate where carried."""
        gain = np.where(self.carried, self.gain_per_s, self.prior_gain_per_s)
        bandwidth = np.where(self.carried, self.bandwidth_per_s, self.prior_bandwidth_per_s)
        actuator = dataclasses.replace(
            robot.actuator,
            position_loop_gain_per_s=(float(gain[0]), float(gain[1])),
            velocity_loop_bandwidth_per_s=(float(bandwidth[0]), float(bandwidth[1])),
        )
        return dataclasses.replace(robot, actuator=actuator)

    def comment_lines(self) -> list[str]:
        """The robot file's comments on the loops."""
        lines = [
            f"# Actuator loops from {self.periods} control periods (goals and positions): "
            "estimate +- standard error [prior], 1/s."
        ]
        for joint in range(2):
            kept = "" if self.carried[joint] else " NOT significant: the prior's kept"
            lines.append(
                f"#   theta{joint + 1}: position_loop_gain_per_s "
                f"{self.gain_per_s[joint]:.4g} +- {self.gain_error_per_s[joint]:.2g} "
                f"[{self.prior_gain_per_s[joint]:.4g}], velocity_loop_bandwidth_per_s "
                f"{self.bandwidth_per_s[joint]:.4g} +- {self.bandwidth_error_per_s[joint]:.2g} "
                f"[{self.prior_bandwidth_per_s[joint]:.4g}]{kept}"
            )
        return lines

    def markdown(
        self, prior_rms_rad: np.ndarray, identified_rms_rad: np.ndarray, on: str
    ) -> list[str]:
        """The report's section on the loops, with the goal prediction on ``on`` by the
        prior's and the identified loops (RMS, rad)."""
        rows = [
            [
                f"θ{joint + 1}",
                f"{self.prior_gain_per_s[joint]:.4g}",
                f"{self.gain_per_s[joint]:.4g} ± {self.gain_error_per_s[joint]:.2g}",
                f"{self.prior_bandwidth_per_s[joint]:.4g}",
                f"{self.bandwidth_per_s[joint]:.4g} ± {self.bandwidth_error_per_s[joint]:.2g}",
                "yes" if self.carried[joint] else "no (prior kept)",
            ]
            for joint in range(2)
        ]
        header = ["joint", "Kp prior, 1/s", "Kp", "ωv prior, 1/s", "ωv", "in the robot file"]
        return [
            "## Actuator loops",
            "",
            "Each joint's position loop gain Kp (`position_loop_gain_per_s`) and velocity loop "
            "bandwidth ωv (`velocity_loop_bandwidth_per_s`) of the model q̈ = ωv (Kp (g − q) − q̇), "
            f"from the goals g and measured positions q of {self.periods} control periods, "
            "1/s (estimate ± standard error: the noise's; where the actuator is not the model, "
            "ωv depends on the motion). The executor leads its goals by them: "
            "g = q + q̇/Kp + q̈/(Kp ωv), half a period ahead.",
            "",
            *markdown_table(header, rows),
            "",
            f"Goal prediction on {on} (RMS of the logged goal less the one each set of loops "
            "needs for the measured positions, filtered):",
            "",
            *markdown_table(
                ["loops", "θ1 mrad", "θ2 mrad"],
                [
                    ["prior"] + [f"{1e3 * v:.4f}" for v in prior_rms_rad],
                    ["identified"] + [f"{1e3 * v:.4f}" for v in identified_rms_rad],
                ],
            ),
        ]


@dataclass(frozen=True)
class _Run:
    """One run of a log on its uniform grid, filtered: the goals held (n, 2) and the
    positions measured (n, 2), rad, and the period, s; rows ``keep`` are past the filter's
    start and end."""

    goal: np.ndarray
    position: np.ndarray
    step_s: float
    keep: slice


def estimate_loops(paths: list[Path], robot: Robot) -> LoopEstimate:
    """Kp and ωv of each joint from the logs at ``paths`` (module docstring); ``robot``'s
    are the prior."""
    runs = _log_runs(paths)
    actuator = robot.actuator
    prior = np.stack(
        [actuator.position_loop_gain_per_s, actuator.velocity_loop_bandwidth_per_s], axis=1
    )
    fits = [_fit(runs, joint, prior[joint]) for joint in range(2)]
    estimate = np.array([fit[0] for fit in fits])  # (2 joints, Kp and ωv)
    error = np.array([fit[1] for fit in fits])
    low, high = LOOP_RATE_RANGE_PER_S
    carried = np.all(
        (estimate >= SIGNIFICANCE * error) & (low <= estimate) & (estimate <= high), axis=1
    )
    return LoopEstimate(
        gain_per_s=estimate[:, 0],
        gain_error_per_s=error[:, 0],
        bandwidth_per_s=estimate[:, 1],
        bandwidth_error_per_s=error[:, 1],
        prior_gain_per_s=prior[:, 0],
        prior_bandwidth_per_s=prior[:, 1],
        carried=carried,
        residual_rad=np.array([fit[2] for fit in fits]),
        periods=sum(run.keep.stop - run.keep.start for run in runs),
    )


def goal_rms(paths: list[Path], robot: Robot) -> np.ndarray:
    """RMS per joint (2,), rad, of the logged goals less those ``robot``'s loops give for
    the measured positions (the one-step relation, filtered; module docstring)."""
    runs = _log_runs(paths)
    actuator = robot.actuator
    gain, bandwidth = actuator.position_loop_gain_per_s, actuator.velocity_loop_bandwidth_per_s
    residuals = [_residual(runs, joint, gain[joint], bandwidth[joint]) for joint in range(2)]
    return np.array([np.sqrt(np.mean(residual**2)) for residual in residuals])


def _fit(runs: list[_Run], joint: int, prior: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(Kp, ωv) of one joint, their standard errors (1/s) and the residual RMS (rad): least
    squares over their logarithms, from the prior's."""
    result = scipy.optimize.least_squares(
        lambda x: _residual(runs, joint, *np.exp(x)), np.log(prior), method="lm"
    )
    jacobian, residual = result.jac, result.fun
    if np.linalg.matrix_rank(jacobian) < 2:
        raise InputError(
            f"logs: theta{joint + 1} does not move enough for its position_loop_gain_per_s "
            "and velocity_loop_bandwidth_per_s; log a motion that accelerates it"
        )
    lags = max(math.ceil(1.0 / (run.step_s * _cutoff(run.step_s))) for run in runs)
    variance = float(np.sum(residual**2)) / max(len(residual) - 2, 1)
    factor = correlation_factor(residual[:, None], lags)
    covariance = factor * variance * np.linalg.inv(jacobian.T @ jacobian)
    estimate = np.exp(result.x)
    return estimate, estimate * np.sqrt(np.diag(covariance)), float(np.sqrt(np.mean(residual**2)))


def _residual(runs: list[_Run], joint: int, gain: float, bandwidth: float) -> np.ndarray:
    """The logged goals less those of the loop model (Kp ``gain``, ωv ``bandwidth``, 1/s)
    for the measured positions, over every run's kept rows, rad."""
    parts = []
    for run in runs:
        b, a, _ = scipy.signal.cont2discrete(
            ([gain * bandwidth], [1.0, bandwidth, gain * bandwidth]), run.step_s, method="zoh"
        )
        b = np.ravel(b)
        q, g = run.position[:, joint], run.goal[:, joint]
        # q_{k+1} + a1 q_k + a2 q_{k-1} = b1 g_k + b2 g_{k-1}, each side over its sum (1 at rest)
        model = (q[2:] + a[1] * q[1:-1] + a[2] * q[:-2]) / np.sum(a)
        held = (b[1] * g[1:-1] + b[2] * g[:-2]) / (b[1] + b[2])
        keep = slice(run.keep.start - 1, run.keep.stop - 1)
        parts.append((held - model)[keep])
    return np.concatenate(parts)


def _cutoff(step_s: float) -> float:
    """The filter's cutoff for a log of this period, Hz."""
    return min(CUTOFF_HZ, 0.2 / step_s)


def _log_runs(paths: list[Path]) -> list[_Run]:
    """Every run of every log, filtered."""
    check_log_rows(paths)
    runs = [run for path in paths for run in _runs(Path(path))]
    if not runs:
        raise InputError(
            f"logs {named(paths)}: no run of {MIN_RUN_PERIODS} periods of the "
            f"{CUTOFF_HZ:g} Hz filter with goals and positions"
        )
    return runs


def _runs(path: Path) -> list[_Run]:
    """The runs of rows that have goals and positions, long enough, on uniform grids."""
    table, _ = read_execution_log(path)
    t = log_values(table, ("time_s",), path)[:, 0]
    goal = log_values(table, ("goal_theta1_rad", "goal_theta2_rad"), path)
    position = log_values(table, ("position_theta1_rad", "position_theta2_rad"), path)
    complete = np.isfinite(t) & np.all(np.isfinite(goal), axis=1)
    complete &= np.all(np.isfinite(position), axis=1)
    runs = []
    for chunk in np.split(np.arange(len(t)), np.flatnonzero(np.diff(complete.astype(int))) + 1):
        if complete[chunk[0]] and len(chunk) > 1:
            run = _uniform_run(path, t[chunk], goal[chunk], position[chunk])
            runs += [] if run is None else [run]
    return runs


def _uniform_run(path: Path, t: np.ndarray, goal: np.ndarray, position: np.ndarray) -> _Run | None:
    """A run on a uniform grid of its median period, the goals held and the positions
    interpolated, filtered; None if shorter than :data:`MIN_RUN_PERIODS` periods of the
    cutoff."""
    step = float(np.median(np.diff(t)))
    if not step > 0.0:
        raise InputError(f"log {path}: time_s does not increase")
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-6)) + 1)
    span = math.ceil(1.0 / (step * _cutoff(step)))
    if len(grid) < MIN_RUN_PERIODS * span:
        return None
    held = goal[np.searchsorted(t, grid + 1e-6 * step, side="right") - 1]
    q = np.stack([np.interp(grid, t, column) for column in position.T], axis=1)
    sos = scipy.signal.butter(FILTER_ORDER, _cutoff(step), fs=1.0 / step, output="sos")
    return _Run(
        goal=scipy.signal.sosfiltfilt(sos, held, axis=0),
        position=scipy.signal.sosfiltfilt(sos, q, axis=0),
        step_s=step,
        keep=slice(span, len(grid) - span),
    )
