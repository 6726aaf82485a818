"""What an execution log's readings give, and how finely: the derivatives the judge
estimates from them, and the resolution of every figure it judges.

**The estimates.** The actuators report position (encoder pulses), velocity (a unit of
0.00199234 rpm on the L54) and current (a unit of 16.11 mA). Speed is the reported
velocity. Acceleration and jerk are the first and second derivatives of the reported
velocity by a quadratic Savitzky–Golay filter over :data:`ACCELERATION_SPAN_S` and
:data:`JERK_SPAN_S` (5 and 11 samples at 100 Hz: at 100 Hz the filters pass motion
slower than about 8 and 4 Hz), on a uniform grid at the loop's period (the velocity
interpolated there where a row is late or missing). A quadratic filter's derivatives are
weighted averages of the true ones with positive weights, so smoothing never raises a
peak; it rounds short peaks off. Second and third differences of the quantised position
would move by 0.17 rad/s² and 17 rad/s³ per pulse at 100 Hz: the velocity is the
finer source.

**The resolution** (:class:`Resolution`) is the largest error rounding to the readings'
units can put into each figure: half a unit of the reading, carried through the filters
(the sum of their weights' magnitudes) and through the kinematics at the judged poses.
A rule whose limit is not above its figure's resolution cannot be told apart from the
rounding: the judge leaves it out and says so (:func:`unresolved_rules`). The plant's true
state, read from a trace, has no rounding.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import savgol_coeffs, savgol_filter

from spm_opt.base.errors import InputError
from spm_opt.cut.contour import direction_rates, surface_speed
from spm_opt.judge.limits import RULES
from spm_opt.model import kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem

ACCELERATION_SPAN_S = 0.04
JERK_SPAN_S = 0.1
"""Spans of the Savitzky–Golay filters that give acceleration and jerk, s, from the first
sample to the last (an odd number of samples: 5 and 11 at 100 Hz)."""

ORDER = 2
"""Polynomial order of the Savitzky–Golay filters."""


def filter_width(span_s: float, period_s: float) -> int:
    """Samples (odd) a filter over ``span_s`` (s) takes at ``period_s`` (s)."""
    return max(2 * int(round(span_s / period_s / 2.0)) + 1, ORDER + 1)


def smoothed_derivatives(
    t: np.ndarray, rate: np.ndarray, period_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """The first and second derivatives (N, k) of rates (N, k) sampled at times t (N,), s:
    quadratic Savitzky–Golay filters over :data:`ACCELERATION_SPAN_S` and
    :data:`JERK_SPAN_S` on a uniform grid at ``period_s`` (s; the rates interpolated onto
    it), read back at t."""
    count = int(np.floor((t[-1] - t[0]) / period_s + 0.5)) + 1
    grid = t[0] + period_s * np.arange(count)
    uniform = np.column_stack([np.interp(grid, t, column) for column in rate.T])
    derivatives = []
    # at the ends, the rate held (acceleration) and the end window's own fit (jerk): each
    # still a positive average of the true derivative, as in the middle
    for order, span, mode in ((1, ACCELERATION_SPAN_S, "nearest"), (2, JERK_SPAN_S, "interp")):
        width = filter_width(span, period_s)
        if count < width:
            raise InputError(
                f"only {t[-1] - t[0]:.3f} s from the plan's start to the log's end: the "
                f"judge smooths over {width} samples at {1.0 / period_s:g} Hz"
            )
        smooth = savgol_filter(
            uniform, width, ORDER, deriv=order, delta=period_s, axis=0, mode=mode
        )
        derivatives.append(np.column_stack([np.interp(t, grid, c) for c in smooth.T]))
    return derivatives[0], derivatives[1]


@dataclass(frozen=True)
class Resolution:
    """The largest error the readings' rounding can put into each judged figure (±).

    Attributes
    ----------
    position_deg : float, deg
        Half an encoder pulse.
    speed_rad_s : float, rad/s
        Half a velocity unit.
    acceleration_rad_s2, jerk_rad_s3 : float
        Half a velocity unit through the filters.
    current_a : float, A
        Half a current unit.
    torque_nm : float, N·m
        Half a current unit through the current map's steepest piece.
    tool_speed_mm_s : float, mm/s
        Half a velocity unit on each joint, at the judged pose that feels it most.
    cut_mm : float, mm
        Half a pulse on each joint, at the judged pose that feels it most: the cut's
        position, which the contour deviation, the landmark visits, the coverage and the
        backtracking measure.
    """

    position_deg: float
    speed_rad_s: float
    acceleration_rad_s2: float
    jerk_rad_s3: float
    current_a: float
    torque_nm: float
    tool_speed_mm_s: float
    cut_mm: float

    def to_dict(self) -> dict[str, float]:
        """Plain data for JSON."""
        return asdict(self)


def filter_gain(span_s: float, order: int, period_s: float) -> float:
    """The largest factor (1/s^order) by which the filter of that span and derivative
    ``order`` can carry an error bounded by 1 in each rate sample."""
    width = filter_width(span_s, period_s)
    weights = savgol_coeffs(width, ORDER, deriv=order, delta=period_s, use="dot")
    return float(np.sum(np.abs(weights)))


def log_resolution(problem: Problem, q: np.ndarray, period_s: float) -> Resolution:
    """The resolution of a log's figures at its judged angles q (N, 2), rad, sampled every
    ``period_s`` (s), for the problem's robot and cut."""
    actuator = problem.robot.actuator
    half_pulse = np.pi / actuator.pulses_per_rev  # rad
    half_rate = 0.5 * float(actuator.rate(1))  # rad/s
    half_current = 0.5 * actuator.current_unit_a
    currents = np.asarray(actuator.current_map.currents_a)
    torques = np.asarray(actuator.current_map.torques_nm)
    steepest = float(np.max(np.abs(np.diff(torques) / np.diff(currents))))
    return Resolution(
        position_deg=half_pulse / DEG,
        speed_rad_s=half_rate,
        acceleration_rad_s2=half_rate * filter_gain(ACCELERATION_SPAN_S, 1, period_s),
        jerk_rad_s3=half_rate * filter_gain(JERK_SPAN_S, 2, period_s),
        current_a=half_current,
        torque_nm=half_current * steepest,
        tool_speed_mm_s=_surface_bound(problem, q, half_rate) / MM,
        cut_mm=_surface_bound(problem, q, half_pulse) / MM,
    )


def _surface_bound(problem: Problem, q: np.ndarray, error: float) -> float:
    """The largest move (m) of the cut on the skull for an error of ``error`` (rad, or
    rad/s for a speed) in each joint, over the poses q (N, 2)."""
    points = kinematics.forward_kinematics(q, 1.0)
    radius, gradient = problem.contour.surface.radius_gradient(points)
    moves = [
        surface_speed(radius, gradient, direction_rates(q, np.eye(2)[joint] * error))
        for joint in range(2)
    ]
    return float(np.max(moves[0] + moves[1]))


UNRESOLVED_RULES = {
    "joint speed": "speed_rad_s",
    "joint acceleration": "acceleration_rad_s2",
    "joint jerk": "jerk_rad_s3",
    "actuator torque": "torque_nm",
    "motor current": "current_a",
    "tool speed": "tool_speed_mm_s",
    "contour deviation": "cut_mm",
    "landmark visit": "cut_mm",
    "coverage": "cut_mm",
    "backtracking": "cut_mm",
}
"""Each rule judged on an estimate from the readings, and the figure of its resolution."""


def unresolved_rules(resolution: Resolution, limits: dict[str, float | None]) -> dict[str, str]:
    """The rules whose limit is not above the resolution of what judges them, each with
    why (one sentence), from ``limits``: rule → the smallest limit it applies (in the
    rule's unit; None: not limited)."""
    found = {}
    for rule, figure in UNRESOLVED_RULES.items():
        limit = limits.get(rule)
        floor = getattr(resolution, figure)
        if limit is not None and floor >= limit:
            unit = RULES[rule].unit
            found[rule] = (
                f"{rule}: the log resolves it to ±{floor:.3g} {unit}, "
                f"not finer than its limit {limit:.3g} {unit}"
            )
    return found
