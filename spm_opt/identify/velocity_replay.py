"""Each velocity loop's bandwidth ωv from the logs' Present Velocity: the logged goals
replayed through the identified robot's closed-loop model, ωv chosen so that the model's
velocities at the logged instants are the robot's.

Goals and positions alone do not tell ωv (:mod:`spm_opt.identify.loop`): the firmware's PI
velocity loop leaves no q̈ term in the goal relation. The velocity read at each cycle does:
it is taken just before the next goal, so it holds what is left of the loop's answer to
the last goal step, which decays at ωv. The replay starts the model (the identified
dynamics, friction, gear losses and rotor inertia, the position loop's Kp, the plant of
:mod:`spm_opt.execution.plant` with the Velocity P Gain giving ωv) at rest where the log's
first reading is and plays the log at the instants its header's ``cycle_timing`` records
(0 on the simulated robot; through the SDK, the read's middle and the goal write some
milliseconds after each row's time): it reads the model's Present Velocity when the row's
read sampled and gives it the row's goal when the write returned, in the order they came
(the loop writes first; a log made before it did reads first). Each joint's ωv
minimises the RMS of the model's velocity less the logged one over the first
:data:`REPLAY_SECONDS` of the logs' plans (a log is replayed from its first reading, through
the approach and the hold at the plan's start, which only set the model's state): a grid
of :data:`GRID_PER_S` for both joints at once (a joint's velocity hardly depends on the
other's ωv), then :data:`REFINEMENTS` halvings of the step about each joint's best. An
estimate is carried only where the grid's best lies inside it and the grid leaves at least
:data:`DISTINCT` times the estimate's residual, and :data:`DISTINCT_UNITS` velocity units
more, on each side of it.

Measured on family plants (:mod:`spm_opt.verify.plant_family`, seed 2026) identified from
30 s of ``problems/identification.toml``'s excitation: the plant's own model replays its log
to 0.18 mrad/s (the velocity unit is 0.21 mrad/s). On the tenth plant (ωv 290 and 285 1/s)
the grid left 46.6 and 50.8 mrad/s at 40 1/s, 5.5 and 7.2 at 320 and 29.3 and 36.7 at 640;
the estimate, 281 and 269 1/s, 1.9 and 1.4 mrad/s, against 23.0 and 16.7 at the prior's 134
and 178. Over the ten plants of ``experiments/compensated_cut.py`` the estimate was within
8 % of the plant's ωv, and the cut predicted on the identified file within 0.0031 mm of the
true cut on 162 of 164 runs at 4 mm/s (up to 0.036 mm with the prior's ωv; the two others
began where a joint stuck off the plan's start). The model's Velocity I Gain is
the firmware's default, which a robot file does not hold: on a plant with twice it, ωv came
out 108 and 269 1/s against 100 and 250 (``tests/test_velocity_replay.py``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.markdown import markdown_table
from spm_opt.execution.log import read_execution_log
from spm_opt.execution.plant import DynamixelPlant, closed_loop_settings
from spm_opt.identify.samples import check_log_rows, log_values
from spm_opt.model.actuator import Actuator
from spm_opt.model.params import Robot

__all__ = [
    "DISTINCT",
    "DISTINCT_UNITS",
    "GRID_PER_S",
    "REFINEMENTS",
    "REPLAY_SECONDS",
    "BandwidthReplay",
    "replay_bandwidth",
]

REPLAY_SECONDS = 10.0
"""How much of the logs is replayed, s, from the first (one period of the identification
excitation; a replay costs about 0.75 s of compute per 10 s of log, and the estimate
about 13 replays)."""
GRID_PER_S = (40.0, 80.0, 160.0, 320.0, 640.0)
"""The ωv first tried for both joints at once, 1/s."""
REFINEMENTS = 4
"""Times the step about each joint's best is halved (in log ωv: from ×2 to ×2^(1/16),
about 4 %), trying one value either side each time."""
DISTINCT = 1.5
"""An estimate is carried where the grid leaves at least this many times its residual on
either side of it ..."""
DISTINCT_UNITS = 5.0
"""... and at least this many Present Velocity units more (a log that hardly moves leaves
residuals of a unit or two at any ωv)."""
_POSITIONS = ("position_theta1_rad", "position_theta2_rad")
_VELOCITIES = ("velocity_theta1_rad_s", "velocity_theta2_rad_s")
_GOALS = ("goal_theta1_rad", "goal_theta2_rad")


@dataclass(frozen=True)
class BandwidthReplay:
    """Each joint's ωv from the replay (θ1, θ2).

    Attributes
    ----------
    bandwidth_per_s : ndarray, shape (2,), 1/s
        The estimate (where not carried, the best the replay found).
    residual_rad_s : ndarray, shape (2,), rad/s
        RMS of the model's velocity less the logged one at the estimate.
    prior_bandwidth_per_s, prior_residual_rad_s : ndarray, shape (2,)
        The robot's ωv before the replay, 1/s, and its residual, rad/s.
    reason : tuple of str
        Per joint, why the estimate is not carried ("" where it is).
    seconds : float
        Log replayed, s (all logs together).
    """

    bandwidth_per_s: np.ndarray
    residual_rad_s: np.ndarray
    prior_bandwidth_per_s: np.ndarray
    prior_residual_rad_s: np.ndarray
    reason: tuple[str, str]
    seconds: float

    @property
    def carried(self) -> np.ndarray:
        """Whether each joint's estimate goes into the robot file (2,), bool."""
        return np.array([not why for why in self.reason])

    def robot(self, robot: Robot) -> Robot:
        """``robot`` with each joint's ωv the estimate where carried."""
        bandwidth = np.where(self.carried, self.bandwidth_per_s, self.prior_bandwidth_per_s)
        actuator = dataclasses.replace(
            robot.actuator, velocity_loop_bandwidth_per_s=(float(bandwidth[0]), float(bandwidth[1]))
        )
        return dataclasses.replace(robot, actuator=actuator)

    def comment_lines(self) -> list[str]:
        """The robot file's comments on the replay."""
        lines = [
            f"# Velocity loop bandwidth from {self.seconds:.1f} s of the logs replayed through "
            "the identified model (Present Velocity RMS of the model less the log):"
        ]
        for joint in range(2):
            lines.append(f"#   theta{joint + 1} velocity_loop_bandwidth_per_s: {self._line(joint)}")
        return lines

    def summary(self) -> str:
        """One line on what the robot file gets."""
        return "velocity loop bandwidth from the replay (1/s): " + "; ".join(
            f"theta{joint + 1} {self._line(joint)}" for joint in range(2)
        )

    def markdown(self) -> list[str]:
        """The report's section on the replay."""
        rows = [
            [
                f"θ{joint + 1}",
                f"{self.prior_bandwidth_per_s[joint]:.4g}",
                f"{1e3 * self.prior_residual_rad_s[joint]:.3f}",
                f"{self.bandwidth_per_s[joint]:.4g}",
                f"{1e3 * self.residual_rad_s[joint]:.3f}",
                "yes" if self.carried[joint] else f"no: {self.reason[joint]}",
            ]
            for joint in range(2)
        ]
        header = ["joint", "ωv before, 1/s", "mrad/s", "ωv replayed, 1/s", "mrad/s", "in the file"]
        return [
            "## Velocity loop bandwidth from the replay",
            "",
            f"The logged goals of {self.seconds:.1f} s replayed through the identified model, "
            "each joint's ωv chosen so that the model's Present Velocity at the logged "
            "instants is the robot's (RMS of the difference, mrad/s).",
            "",
            *markdown_table(header, rows),
            "",
        ]

    def _line(self, joint: int) -> str:
        """What one joint's file value is and why."""
        prior = self.prior_bandwidth_per_s[joint]
        before = f"[{prior:.4g}: {1e3 * self.prior_residual_rad_s[joint]:.3g} mrad/s]"
        if self.carried[joint]:
            found = self.bandwidth_per_s[joint], 1e3 * self.residual_rad_s[joint]
            return f"{found[0]:.4g} ({found[1]:.3g} mrad/s) {before}"
        return f"{prior:.4g} kept ({self.reason[joint]}) {before}"


def replay_bandwidth(paths: list[Path], robot: Robot) -> BandwidthReplay:
    """Each joint's ωv from the logs at ``paths`` replayed through ``robot``'s closed-loop
    model (module docstring); ``robot``'s own ωv is the prior."""
    check_log_rows(paths)
    logs, left = [], REPLAY_SECONDS
    for path in paths:
        if left <= 0.0:
            break
        logs.append(_replayed_log(Path(path), left))
        left -= logs[-1].judged_s
    grid = np.array(GRID_PER_S)
    residuals = np.array([_residual(logs, robot, (w, w)) for w in grid])  # (grid, 2)
    best = np.argmin(residuals, axis=0)
    estimate, residual = grid[best], residuals[best, [0, 1]]
    step = np.log(grid[1] / grid[0])
    for _ in range(REFINEMENTS):
        step /= 2.0
        for side in (-1.0, 1.0):
            trial = estimate * np.exp(side * step)
            found = _residual(logs, robot, (float(trial[0]), float(trial[1])))
            better = found < residual
            estimate = np.where(better, trial, estimate)
            residual = np.where(better, found, residual)
    reason, unit = ["", ""], float(robot.actuator.rate(1))
    for joint in range(2):
        left, right = residuals[: best[joint], joint], residuals[best[joint] + 1 :, joint]
        if not (left.size and right.size):
            reason[joint] = f"the best of {grid[0]:.0f}–{grid[-1]:.0f} 1/s is at the end"
        elif min(left.max(), right.max()) < DISTINCT * residual[joint]:
            reason[joint] = (
                f"the velocities do not single it out: {grid[0]:.0f}–{grid[-1]:.0f} 1/s leave "
                f"less than {DISTINCT:g} times the best's {1e3 * residual[joint]:.3g} mrad/s "
                "on one side"
            )
        elif min(left.max(), right.max()) - residual[joint] < DISTINCT_UNITS * unit:
            reason[joint] = (
                f"the logs move too little: {grid[0]:.0f}–{grid[-1]:.0f} 1/s leave under "
                f"{DISTINCT_UNITS:g} velocity units ({1e3 * DISTINCT_UNITS * unit:.2g} mrad/s) "
                "more than the best on one side"
            )
    prior = np.array(robot.actuator.velocity_loop_bandwidth_per_s, dtype=float)
    return BandwidthReplay(
        bandwidth_per_s=estimate,
        residual_rad_s=residual,
        prior_bandwidth_per_s=prior,
        prior_residual_rad_s=_residual(logs, robot, (float(prior[0]), float(prior[1]))),
        reason=(reason[0], reason[1]),
        seconds=sum(log.judged_s for log in logs),
    )


@dataclass(frozen=True)
class _Log:
    """A log's replayed rows: time (n,), s; positions, velocities (n, 2), rad and rad/s
    (NaN where not read); goals (n, 2), rad (NaN where none was written); whether each
    row's velocity is judged (n,), bool (from the plan's first row on); when after each
    row's time the read sampled and the goal was written (the header's ``cycle_timing``,
    0 where absent), s."""

    time_s: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    goal: np.ndarray
    judged: np.ndarray
    read_s: float
    written_s: float

    @property
    def judged_s(self) -> float:
        """How long the judged rows last, s."""
        return float(self.time_s[-1] - self.time_s[self.judged][0])


def _replayed_log(path: Path, seconds: float) -> _Log:
    """A log from its first row with a reading to ``seconds`` after its plan's first row
    (its first reading, if later or if it has no plan phase)."""
    table, header = read_execution_log(path)
    time_s = log_values(table, ("time_s",), path)[:, 0]
    position = log_values(table, _POSITIONS, path)
    read = np.flatnonzero(np.isfinite(time_s) & np.all(np.isfinite(position), axis=1))
    if len(read) < 2:
        raise InputError(f"log {path}: fewer than two rows with both joints' positions")
    plan = np.flatnonzero(table["phase"].astype(str).to_numpy() == "plan")
    start = max(time_s[read[0]], time_s[plan[0]]) if len(plan) else time_s[read[0]]
    rows = np.arange(len(time_s)) >= read[0]
    rows &= np.isfinite(time_s) & (time_s <= start + seconds)
    velocity, goal = log_values(table, _VELOCITIES, path), log_values(table, _GOALS, path)
    timing = header.get("cycle_timing") or {}
    return _Log(
        time_s[rows],
        position[rows],
        velocity[rows],
        goal[rows],
        time_s[rows] >= start,
        float(timing.get("read_s", 0.0)),
        float(timing.get("goal_written_s", 0.0)),
    )


def _write(plant: DynamixelPlant, actuator: Actuator, time_s: float, goal: np.ndarray) -> None:
    """Give ``plant`` a logged goal (rad; none where NaN) at ``time_s`` (s)."""
    plant.advance_to(time_s)
    if np.all(np.isfinite(goal)):
        plant.goal_position_rad[:] = actuator.angle(actuator.pulses(goal))


def _residual(logs: list[_Log], robot: Robot, bandwidth: tuple[float, float]) -> np.ndarray:
    """RMS per joint (2,), rad/s, of the model's Present Velocity less the logged one, the
    model ``robot`` with ωv ``bandwidth`` (1/s per joint)."""
    model = dataclasses.replace(
        robot,
        actuator=dataclasses.replace(robot.actuator, velocity_loop_bandwidth_per_s=bandwidth),
    )
    settings = closed_loop_settings(model)
    actuator = model.actuator
    squares, counted = np.zeros(2), np.zeros(2)
    for log in logs:
        start = log.position[0] - np.asarray(model.encoder_offset)
        plant = DynamixelPlant(model, settings, start)
        for joint in range(2):
            plant.enable_torque(joint, True)
        replayed = np.empty_like(log.velocity)
        write_first = log.written_s <= log.read_s  # the loop's order (its timing says)
        for k, now in enumerate(log.time_s - log.time_s[0]):
            if write_first:
                _write(plant, actuator, now + log.written_s, log.goal[k])
            plant.advance_to(now + log.read_s)
            replayed[k] = actuator.rate(plant.present_velocity_units())
            if not write_first:
                _write(plant, actuator, now + log.written_s, log.goal[k])
        error = replayed - log.velocity
        seen = np.isfinite(error) & log.judged[:, None]
        squares += np.sum(np.where(seen, error, 0.0) ** 2, axis=0)
        counted += np.sum(seen, axis=0)
    return np.sqrt(squares / np.maximum(counted, 1))
