"""Each actuator's position and velocity loop identified from execution logs: the goals sent
and the positions measured.

The loop model of :mod:`spm_opt.execution.tracking`, per joint: q̈ = ωv (Kp (g − q) − q̇),
Kp the position loop's gain (``position_loop_gain_per_s``, 1/s: position error to rate
command) and ωv the velocity loop's bandwidth (``velocity_loop_bandwidth_per_s``, 1/s: the
rate follows its command as a first-order lag). Each goal g_k is held over its control
period [t_k, t_k + T) and the position q_k is read at t_k, so the model's exact
discretisation (zero-order hold, ``scipy.signal.cont2discrete``) relates them one period
ahead:

    q_{k+1} + α1 q_k + α2 q_{k−1} = β1 g_k + β2 g_{k−1},

α and β functions of Kp, ωv and T. Each side divided by its sum (equal: at rest q = g), the
difference is the logged goal less the one the model needs for the measured positions (as
T → 0, g − q − q̇/Kp − q̈/(Kp ωv): the executor's lead), rad. Kp and ωv of each joint
minimise its sum of squares over every period of the logs, all phases but the hold at the
plan's start (:func:`~spm_opt.identify.samples.held_at_the_start`)
(``scipy.optimize.least_squares`` over their logarithms, from the prior's, within the range
a robot file accepts, :data:`~spm_opt.model.actuator.LOOP_RATE_RANGE_PER_S`), goals and
positions both through the same zero-phase low-pass filter first (4th-order Butterworth
forward and back at :data:`CUTOFF_HZ`, which leaves the relation exact and takes out the
encoder's rounding, which the relation's second differences would amplify). A log is put on
a uniform grid of its median period, the goals held (a missed cycle holds its goal twice)
and the positions interpolated; rows without a position split it into runs. The read's and
the write's latency within a cycle count as part of the loop, as they do for the executor's
goals. Standard errors: σ² (JᵀJ)⁻¹ times the residuals' correlation factor
(:func:`~spm_opt.identify.samples.correlation_factor` over one period of the cutoff).

What reaches the robot file. The standard errors measure the noise, not a plant that is not
the model, and shrink with the log's length while such a plant's bias does not (θ2's ωv
came out 409 ± 50 1/s over 6 s and 417 ± 29 over 20 s of the excitation below, against the
plant's 178). So each estimate, Kp and ωv of each joint on its own, is carried only if it
lies inside the range a robot file accepts (not at its end), is at least
:data:`SIGNIFICANCE` standard errors, and its *misfit* is at most :data:`TOLERANCE`: ‖r‖
√[(JᵀJ)⁻¹]_kk over the log-parameters, the relative change of the estimate whose effect on
the goals, beyond what the other parameter can take up, is as large as all the model leaves
unexplained. Where the misfit is larger, the log cannot tell the estimate from the model's
error: it is reported "not identifiable from this log" with the reason, and the prior is
kept. The misfit is no bound on the error (the part of a mismatch the parameters absorb
does not show in the residual: Kp below came out up to 4.8 % high with misfits of
1.4–2.3 %); it says when the evidence is too weak to carry an estimate at all.

Why ωv came out absurd, measured on the simulated robot (:mod:`spm_opt.execution.plant`)
whose plant is the model prototype.toml, driven by the 6 s two-sine excitation of
``tests/test_identify_loop.py`` (``plant_log``, other gains from
``spm_opt.execution.plant.gains_for_rates``) unless said otherwise. The plant's velocity
loop is the firmware's PI loop, τ = K (Kp (g − q) − q̇) + Ki ∫(Kp (g − q) − q̇), on the
joint's inertia M. Its goal relation is 1/G(s) = 1 + s/Kp + s³/(Kp (ωi + ωv s)), ωv = K/M
and ωi = Ki/M (5680 and 7540 1/s² at θ = 0 against ωv Kp = 4300 and 5710): it has no q̈
term at all, because the integral takes up the lag an acceleration would leave. The model's
ωv is the inverse of that term's coefficient, so it is infinite for this plant, and the fit
lands wherever the effects the model leaves out put it. The old fit (unbounded,
Levenberg–Marquardt) gave ωv 4.3e8 and 1.9e4 1/s at 100 Hz, 2223 and 1915 at 500 Hz, with
the slides' friction off (mu = 0); with it, 446 and 409 at 100 Hz, 432 and 399 at 500 Hz,
and 119 and 199 (100 Hz), 120 and 200 (500 Hz) over the gentle 120 s excitation of
``tests/test_identify.py``, all against the plant's ωv 134 and 178
(``spm_opt.execution.plant.loop_rates``). Over 24 plants with other gains (Kp 20–60 1/s, ωv
60–300 1/s, random, 6 s at 100 and 500 Hz alternately) ωv came out 380–500 1/s whatever the
plant's, with misfits of 81–207 %: none is carried now, while Kp came out 2.3–4.8 % above
the plant's with misfits 1.4–2.3 %, all carried (the plant reads q at the start of each
1 ms step, so a ramp lags it as if Kp were Kp/(1 − Kp · 1 ms)). It was not the zero-order
hold or ωv T ≈ 1.3 at 100 Hz (the relation is exact in T: from the loop model's own
integration, ``test_the_loops_of_an_exact_integration_come_out``, Kp and ωv come out within
1e-5 and 4e-4 at 100 and 500 Hz, misfits under 1 %), nor the filter (cutoff 2 to 20 Hz on
the 120 s 100 Hz log: Kp moved under 0.2 %, ωv over 103–145 and 167–236 1/s, misfits above
90 % throughout), nor the starting point (from (Kp, ωv) = (20, 60) to (40, 3000) the fit
ends within 0.1 % of the same place). Nor does the PI loop's own structure help: fitted as
a third-order model (Kp, ωv, ωi, the same exact discretisation), ωv came out 294 and 295
without friction and 23–28 and 56–61 with it (6 and 20 s): the velocity P gain shows in
smooth goals only through the phase of the s³ term (ωv ω/ωi, 15 % of a term about 1e-3 of
the motion at 1 Hz), below the plant's 1 ms step and its friction. Without the integral
(Velocity I Gain 0) ωv came out 24–169 1/s against 100–300, gravity's error (which a P-P
loop leaves) dominating, misfits 33–104 %. So ωv is not identifiable from goals and
positions on this plant; the report says so and keeps the prior.

On ``prototype_plant.toml`` (heavier, rotor inertia, viscous friction, gear losses; ωv 87
and 116 1/s) the fast 6 s excitation at 100 Hz gives Kp 33.06 and 32.73 (carried) and ωv 81
and 83 (misfits 43 % and 25 %, not carried); the 120 s gentle one, ωv 46 and 61. That q̈
coefficient, which the plant's viscous friction and gear losses leave, still leads this
plant well: the 6 s excitation's RMS tracking error was 0.0183° and 0.0361° led by
prototype.toml's loops, 0.0143° and 0.0344° by the carried Kp with the prior's ωv, 0.0117°
and 0.0178° by both raw estimates; but it is not the velocity loop's bandwidth the robot
file names, and it depends on the motion.
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
    held_at_the_start,
    log_values,
    named,
)
from spm_opt.identify.velocity_replay import BandwidthReplay
from spm_opt.model.actuator import LOOP_RATE_RANGE_PER_S
from spm_opt.model.params import Robot

CUTOFF_HZ = 5.0
"""Cutoff of the zero-phase filter on goals and positions, Hz (at most a fifth of a log's
rate): above the plans' band; on the simulated robot's 120 s logs Kp moved by under 0.2 %
from 2 to 20 Hz."""
SIGNIFICANCE = 2.0
"""An estimate is carried only if it is at least this many standard errors."""
TOLERANCE = 0.1
"""An estimate is carried only if the model's misfit could move it by at most this share
(its ``misfit``: the relative change whose effect on the goals, beyond what the other
parameter can take up, is as large as the residual; module docstring)."""
MIN_RUN_PERIODS = 4
"""Shortest run used, in periods of the cutoff (one at each end is trimmed: the filter's
start and end)."""
NAMES = ("position_loop_gain_per_s", "velocity_loop_bandwidth_per_s")
"""The robot file's names of Kp and ωv."""


@dataclass(frozen=True)
class LoopEstimate:
    """The loops' parameters per joint (θ1, θ2), estimated and prior.

    Attributes
    ----------
    gain_per_s, gain_error_per_s, gain_misfit : ndarray, shape (2,)
        Kp, its standard error, 1/s, and its misfit (:data:`TOLERANCE`), a share.
    bandwidth_per_s, bandwidth_error_per_s, bandwidth_misfit : ndarray, shape (2,)
        ωv, its standard error, 1/s, and its misfit, a share.
    prior_gain_per_s, prior_bandwidth_per_s : ndarray, shape (2,)
        The problem's robot's, 1/s.
    gain_reason, bandwidth_reason : tuple of str
        Per joint, why the estimate is not identifiable from the logs ("" where it is):
        where not, the identified robot keeps the prior's.
    residual_rad : ndarray, shape (2,)
        RMS of the logged goals less the estimated loops' (filtered), rad.
    periods : int
        Control periods used.
    replay : BandwidthReplay or None
        ωv from the logs' velocities replayed through the identified model
        (:func:`~spm_opt.identify.velocity_replay.replay_bandwidth`): where present, it
        decides each joint's ωv in the robot file.
    """

    gain_per_s: np.ndarray
    gain_error_per_s: np.ndarray
    gain_misfit: np.ndarray
    bandwidth_per_s: np.ndarray
    bandwidth_error_per_s: np.ndarray
    bandwidth_misfit: np.ndarray
    prior_gain_per_s: np.ndarray
    prior_bandwidth_per_s: np.ndarray
    gain_reason: tuple[str, str]
    bandwidth_reason: tuple[str, str]
    residual_rad: np.ndarray
    periods: int
    replay: BandwidthReplay | None = None

    @property
    def gain_carried(self) -> np.ndarray:
        """Whether each joint's Kp estimate goes into the robot file (2,), bool."""
        return np.array([not reason for reason in self.gain_reason])

    @property
    def bandwidth_carried(self) -> np.ndarray:
        """Whether each joint's ωv estimate goes into the robot file (2,), bool."""
        return np.array([not reason for reason in self.bandwidth_reason])

    def robot(self, robot: Robot) -> Robot:
        """``robot`` with each joint's loop parameters the estimate where carried (ωv the
        replay's, where there is one)."""
        gain = np.where(self.gain_carried, self.gain_per_s, self.prior_gain_per_s)
        bandwidth = np.where(
            self.bandwidth_carried, self.bandwidth_per_s, self.prior_bandwidth_per_s
        )
        actuator = dataclasses.replace(
            robot.actuator,
            position_loop_gain_per_s=(float(gain[0]), float(gain[1])),
            velocity_loop_bandwidth_per_s=(float(bandwidth[0]), float(bandwidth[1])),
        )
        led = dataclasses.replace(robot, actuator=actuator)
        return led if self.replay is None else self.replay.robot(led)

    def _kept(self, name: str, prior: float) -> str:
        """What the robot file gets where the goals do not identify ``name`` (prior, 1/s)."""
        if self.replay is not None and name == NAMES[1]:
            return "the replay below decides"
        return f"the prior's {prior:.4g} kept"

    def _entries(self) -> list[tuple[int, str, float, float, float, str]]:
        """(joint, name, estimate, error, prior, reason) of each joint's Kp and ωv."""
        return [
            (joint, name, float(value[joint]), float(error[joint]), float(prior[joint]), why)
            for joint in range(2)
            for name, value, error, prior, why in (
                (
                    NAMES[0],
                    self.gain_per_s,
                    self.gain_error_per_s,
                    self.prior_gain_per_s,
                    self.gain_reason[joint],
                ),
                (
                    NAMES[1],
                    self.bandwidth_per_s,
                    self.bandwidth_error_per_s,
                    self.prior_bandwidth_per_s,
                    self.bandwidth_reason[joint],
                ),
            )
        ]

    def comment_lines(self) -> list[str]:
        """The robot file's comments on the loops."""
        lines = [
            f"# Actuator loops from {self.periods} control periods (goals and positions): "
            "estimate +- standard error [prior], 1/s."
        ]
        for joint, name, value, error, prior, why in self._entries():
            lines.append(f"#   theta{joint + 1} {name}: {value:.4g} +- {error:.2g} [{prior:.4g}]")
            if why:
                kept = self._kept(name, prior)
                lines.append(f"#     not identifiable from this log ({why}): {kept}")
        return lines + ([] if self.replay is None else self.replay.comment_lines())

    def summary(self) -> str:
        """One line on what the robot file gets: each value, or the prior's and why."""
        parts = []
        for joint, name, value, _, prior, why in self._entries():
            if self.replay is not None and name == NAMES[1]:
                continue
            kept = f"{prior:.4g} (prior; not identifiable: {why})" if why else f"{value:.4g}"
            parts.append(f"theta{joint + 1} {name} {kept}")
        line = "actuator loops (1/s): " + "; ".join(parts)
        return line if self.replay is None else f"{line}; {self.replay.summary()}"

    def markdown(
        self, prior_rms_rad: np.ndarray, identified_rms_rad: np.ndarray, on: str
    ) -> list[str]:
        """The report's section on the loops, with the goal prediction on ``on`` by the
        prior's and the identified loops (RMS, rad)."""
        bandwidth_carried = self.bandwidth_carried if self.replay is None else self.replay.carried
        rows = [
            [
                f"θ{joint + 1}",
                f"{self.prior_gain_per_s[joint]:.4g}",
                f"{self.gain_per_s[joint]:.4g} ± {self.gain_error_per_s[joint]:.2g}",
                f"{100 * self.gain_misfit[joint]:.3g}",
                f"{self.prior_bandwidth_per_s[joint]:.4g}",
                f"{self.bandwidth_per_s[joint]:.4g} ± {self.bandwidth_error_per_s[joint]:.2g}",
                f"{100 * self.bandwidth_misfit[joint]:.3g}",
                ", ".join(
                    label
                    for label, carried in (
                        ("Kp", self.gain_carried[joint]),
                        ("ωv", bandwidth_carried[joint]),
                    )
                    if carried
                )
                or "neither (prior kept)",
            ]
            for joint in range(2)
        ]
        header = [
            "joint",
            "Kp prior, 1/s",
            "Kp",
            "misfit %",
            "ωv prior, 1/s",
            "ωv",
            "misfit %",
            "in the robot file",
        ]
        reasons = [
            f"- θ{joint + 1} `{name}`: not identifiable from this log ({why}); "
            f"{self._kept(name, prior)}."
            for joint, name, _, _, prior, why in self._entries()
            if why
        ]
        return [
            "## Actuator loops",
            "",
            "Each joint's position loop gain Kp (`position_loop_gain_per_s`) and velocity loop "
            "bandwidth ωv (`velocity_loop_bandwidth_per_s`) of the model q̈ = ωv (Kp (g − q) − q̇), "
            f"from the goals g and measured positions q of {self.periods} control periods, "
            "1/s (estimate ± standard error: the noise's). The misfit is the relative change "
            "of an estimate whose effect on the goals is as large as what the model leaves "
            f"unexplained; above {100 * TOLERANCE:g} % the log cannot tell it. The executor "
            "leads its goals by them: g = q + q̇/Kp + q̈/(Kp ωv), half a period ahead.",
            "",
            *markdown_table(header, rows),
            "",
            *(reasons + [""] if reasons else []),
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
            *([] if self.replay is None else ["", *self.replay.markdown()]),
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


@dataclass(frozen=True)
class _Fit:
    """One joint's (Kp, ωv), 1/s, their standard errors, 1/s, and misfits (shares), the
    residual's RMS, rad."""

    estimate: np.ndarray
    error: np.ndarray
    misfit: np.ndarray
    residual_rad: float


def estimate_loops(paths: list[Path], robot: Robot) -> LoopEstimate:
    """Kp and ωv of each joint from the logs at ``paths`` (module docstring); ``robot``'s
    are the prior."""
    runs = _log_runs(paths)
    actuator = robot.actuator
    prior = np.stack(
        [actuator.position_loop_gain_per_s, actuator.velocity_loop_bandwidth_per_s], axis=1
    )
    fits = [_fit(runs, joint, prior[joint]) for joint in range(2)]
    reasons = [[_reason(fit, k) for fit in fits] for k in range(2)]
    return LoopEstimate(
        gain_per_s=np.array([fit.estimate[0] for fit in fits]),
        gain_error_per_s=np.array([fit.error[0] for fit in fits]),
        gain_misfit=np.array([fit.misfit[0] for fit in fits]),
        bandwidth_per_s=np.array([fit.estimate[1] for fit in fits]),
        bandwidth_error_per_s=np.array([fit.error[1] for fit in fits]),
        bandwidth_misfit=np.array([fit.misfit[1] for fit in fits]),
        prior_gain_per_s=prior[:, 0],
        prior_bandwidth_per_s=prior[:, 1],
        gain_reason=(reasons[0][0], reasons[0][1]),
        bandwidth_reason=(reasons[1][0], reasons[1][1]),
        residual_rad=np.array([fit.residual_rad for fit in fits]),
        periods=sum(run.keep.stop - run.keep.start for run in runs),
    )


def _reason(fit: _Fit, k: int) -> str:
    """Why parameter ``k`` (0: Kp, 1: ωv) of ``fit`` is not identifiable; "" if it is."""
    value, error, misfit = fit.estimate[k], fit.error[k], fit.misfit[k]
    low, high = LOOP_RATE_RANGE_PER_S
    if not low * (1.0 + 1e-3) < value < high * (1.0 - 1e-3):
        return (
            f"the fit reaches {value:.4g} 1/s, the end of the range a robot file accepts "
            f"({low:g}–{high:g} 1/s)"
            + (": the goals show no velocity-loop lag" if k == 1 and value > low else "")
        )
    if not misfit <= TOLERANCE:
        return (
            f"a change of {100 * misfit:.3g} % in it moves the goals by no more than the "
            f"model's misfit, {1e3 * fit.residual_rad:.2g} mrad RMS"
        )
    if not value >= SIGNIFICANCE * error:
        return f"{value:.4g} ± {error:.2g} 1/s: under {SIGNIFICANCE:g} standard errors"
    return ""


def goal_rms(paths: list[Path], robot: Robot) -> np.ndarray:
    """RMS per joint (2,), rad, of the logged goals less those ``robot``'s loops give for
    the measured positions (the one-step relation, filtered; module docstring)."""
    runs = _log_runs(paths)
    actuator = robot.actuator
    gain, bandwidth = actuator.position_loop_gain_per_s, actuator.velocity_loop_bandwidth_per_s
    residuals = [_residual(runs, joint, gain[joint], bandwidth[joint]) for joint in range(2)]
    return np.array([np.sqrt(np.mean(residual**2)) for residual in residuals])


def _fit(runs: list[_Run], joint: int, prior: np.ndarray) -> _Fit:
    """(Kp, ωv) of one joint: least squares over their logarithms, from the prior's, within
    the range a robot file accepts."""
    bounds = np.log(LOOP_RATE_RANGE_PER_S)
    result = scipy.optimize.least_squares(
        lambda x: _residual(runs, joint, *np.exp(x)),
        np.clip(np.log(prior), *bounds),
        bounds=tuple(bounds),
    )
    jacobian, residual = result.jac, result.fun
    if not np.any(jacobian[:, 0]):
        raise InputError(
            f"logs: theta{joint + 1} does not move enough for its position_loop_gain_per_s "
            "and velocity_loop_bandwidth_per_s; log a motion that accelerates it"
        )
    # per unit of log θ_k, the goals' change the other parameter cannot take up, squared
    normal = jacobian.T @ jacobian
    sensitivity = np.array(
        [
            normal[k, k] - (normal[0, 1] ** 2 / normal[1 - k, 1 - k] if normal[1 - k, 1 - k] else 0)
            for k in range(2)
        ]
    )
    with np.errstate(divide="ignore"):
        spread = np.where(sensitivity > 0.0, 1.0 / np.sqrt(np.maximum(sensitivity, 0.0)), np.inf)
    lags = max(math.ceil(1.0 / (run.step_s * _cutoff(run.step_s))) for run in runs)
    variance = float(np.sum(residual**2)) / max(len(residual) - 2, 1)
    factor = correlation_factor(residual[:, None], lags)
    estimate = np.exp(result.x)
    return _Fit(
        estimate=estimate,
        error=estimate * np.sqrt(factor * variance) * spread,
        misfit=float(np.linalg.norm(residual)) * spread,
        residual_rad=float(np.sqrt(np.mean(residual**2))),
    )


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
    complete &= np.all(np.isfinite(position), axis=1) & ~held_at_the_start(table)
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
