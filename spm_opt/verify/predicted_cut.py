"""The predicted cut: a plan run through the robot's closed-loop model before anything moves,
and judged as a run's true cut is.

The model is the simulated robot whose plant is the robot file: its dynamics, friction, gear
losses, rotor inertia and encoder zeros, under two Dynamixel controllers with the file's
loops (Kp and ωv, as the control table's whole gains give them:
:func:`~spm_opt.execution.plant.gains_for_rates`; the Velocity I Gain the table's default),
their Velocity and Torque Limits, and the sensors' resolution. The executor drives it with
the run's settings (rate, lead, starting feed) on a virtual clock, from the plan's start
(held there until at rest, as a run is), and
:func:`~spm_opt.verify.executed_cut.evaluate_log` judges the plant's true state against the
whole contour tolerance, as it judges a run's trace, and by the robot's limits
(:attr:`PredictedCut.broken_limits`: where a joint sticks on its friction and breaks away,
the run breaks acceleration and jerk limits its plan keeps). A run predicted within a joint's
speed, acceleration or jerk limit by less than a margin (:data:`LIMIT_SHARES`) does not
keep it either (:attr:`PredictedCut.keeps_limits`). A robot file identified from
the robot's own logs (``spm-opt identify``) makes the model that robot.

What the model cannot know, the prediction does not hold: feed changes made during the run,
a plant that differs from the file, the stick-slip's scatter from run to run.
"""

from __future__ import annotations

import dataclasses
import logging
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from spm_opt.cut.cut_checks import stretch
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot
from spm_opt.execution.backend import CLOCK_EPSILON_S
from spm_opt.execution.feed import FEED_STEP
from spm_opt.execution.log import read_execution_log
from spm_opt.execution.plant import closed_loop_settings
from spm_opt.judge.limits import ROBOT_RULES, contour_tube
from spm_opt.judge.report import Violation
from spm_opt.model import kinematics
from spm_opt.model.params import MM, Robot
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.executed_cut import ExecutionReport, evaluate_log
from spm_opt.verify.followed import Followed, followed_in_log

_EXECUTION_LOG = logging.getLogger("spm_opt.execution")

LIMIT_SHARES: dict[str, float] = {"speed": 0.95, "acceleration": 0.9, "jerk": 0.9}
"""The share of each joint's speed, acceleration and jerk limit a predicted run may reach
and still count as keeping it: the margin for what the model does not see. Measured on the
family of plants and through the actuators' protocol emulator: a plant's jerk where a joint
breaks away came to 7 % above its identified model's prediction (101.7 % of the limit
against 94.8 %), and the real-time timing of the goals added up to 3.6 % to the joint speed
the model predicted (100.2 % against 96.7 %). Over the family study's 266 true runs
(experiments/compensated_cut.py), where a figure was predicted at half its limit or more,
the true share came to at most 1.074 times the predicted for jerk and 1.115 for
acceleration (once: 95.8 % against 85.9 %); no figure predicted within its margin broke the
limit on the true run. Through the emulator, over 8 runs of each hardware plan, the joint
speed came to at most 1.032 times its prediction, and the jerk, in single runs whose goals
arrived late, up to 1.51 times."""


@dataclasses.dataclass(frozen=True)
class PredictedCut:
    """The judgement of a plan's predicted run.

    Attributes
    ----------
    report : ExecutionReport
        The judge's report of the model's true state over the run (``angles`` "true").
    robot : str
        The name of the robot file the model is.
    tube_mm : float or None, mm
        The contour tolerance the cut is judged against (None: the problem sets none).
    farthest_at : str
        Where along the contour the cut is farthest from it.
    time_s : ndarray (N,), s
        The predicted run's times, on its log's clock (the plan starts at its first).
    angles_rad : ndarray (N, 2), rad
        The model's true joint angles at those times.
    followed : Followed
        The plan-phase cycles: their plan times, references and the model's true angles.
    """

    report: ExecutionReport
    robot: str
    tube_mm: float | None
    farthest_at: str
    time_s: np.ndarray
    angles_rad: np.ndarray
    followed: Followed

    @property
    def deviation_mm(self) -> float:
        """The predicted cut's largest distance from the contour, mm."""
        return self.report.max_contour_deviation_mm

    @property
    def inside(self) -> bool:
        """Whether the predicted run completes and the judge finds its cut in the tube."""
        broken = {violation.rule for violation in self.report.violations}
        return self.report.completed and "contour deviation" not in broken

    @property
    def broken_limits(self) -> list[Violation]:
        """The robot's limits the predicted run breaks (the rules that judge the robot:
        joint range, speed, acceleration, jerk, torque, current, singularity), the worst
        against its limit first."""
        broken = [v for v in self.report.violations if v.rule in ROBOT_RULES]
        return sorted(broken, key=lambda v: -abs(v.worst) / max(abs(v.allowed), 1e-12))

    @property
    def past_margin(self) -> list[tuple[str, float]]:
        """The joints' speed, acceleration and jerk the predicted run takes past their share
        of the limit (:data:`LIMIT_SHARES`), each with its share ("theta2 jerk", 0.96), the
        largest over its margin first."""
        return past_margin(self.report.limit_shares)

    @property
    def keeps_limits(self) -> bool:
        """Whether the predicted run completes, breaks no robot limit and keeps each joint
        limit's margin (:data:`LIMIT_SHARES`)."""
        return self.report.completed and not self.broken_limits and not self.past_margin

    def limits_line(self) -> str:
        """One line: the robot's limit the predicted run breaks worst and how many more, or
        else the joint limit whose margin it takes most of; "" if it keeps them all."""
        broken, past = self.broken_limits, self.past_margin
        if broken:
            more = f", and {len(broken) - 1} more" if len(broken) > 1 else ""
            return f"predicted run on {self.robot} breaks {broken[0]}{more}"
        if not past:
            return ""
        (name, share), more = past[0], f", and {len(past) - 1} more" if len(past) > 1 else ""
        return (
            f"predicted run on {self.robot} takes {name} to {share:.1%} of its limit, past the "
            f"{_margin(name):.0%} kept for what the model does not see{more}"
        )

    def summary(self) -> str:
        """One line: the predicted distance, where, against the tube."""
        if not self.report.completed:
            return f"predicted run on {self.robot} does not complete: {self.report.outcome}"
        where = f" ({self.farthest_at})"
        if self.tube_mm is None:
            return (
                f"predicted cut on {self.robot}: {self.deviation_mm:.3f} mm from the contour{where}"
            )
        side = "inside" if self.inside else "outside"
        return (
            f"predicted cut on {self.robot}: {self.deviation_mm:.3f} mm from the contour at "
            f"its farthest{where}, {side} the {self.tube_mm:g} mm tube"
        )


def predict_cut(
    problem: Problem,
    trajectory: Trajectory,
    robot: Robot | None = None,
    settings: ExecutionSettings | None = None,
) -> PredictedCut:
    """Run ``trajectory`` through the closed-loop model of ``robot`` (default: the
    problem's) with the executor's ``settings`` and judge its true cut (see the module's
    docstring)."""
    robot = robot or problem.robot
    settings = dataclasses.replace(settings or ExecutionSettings(), approach=False)
    backend = SimulatedRobot(
        problem.robot,
        start_rad=trajectory.position(trajectory.start_time),
        settings=closed_loop_settings(robot),
        plant_robot=robot,
    )
    with tempfile.TemporaryDirectory(prefix="spm_opt_predict_") as folder:
        log, trace = Path(folder) / "predicted.csv", Path(folder) / "predicted.npz"
        with _quiet(_EXECUTION_LOG):
            Executor(problem, backend, settings).run(trajectory, log)
        backend.trace.save(trace)
        report = evaluate_log(problem, log, trace, other_problem=settings.other_problem).true
        table, header = read_execution_log(log)
    assert report is not None  # a trace was given
    tube = contour_tube(problem, executed=True)
    state = backend.trace.arrays(header["clock_origin_s"])
    planned = table.loc[table["phase"].astype(str) == "plan", "time_s"]
    begun = planned.iloc[0] if len(planned) else -np.inf
    judged = state["time_s"] >= begun - CLOCK_EPSILON_S  # as the judge: from the plan on
    return PredictedCut(
        report=report,
        robot=robot.name,
        tube_mm=None if tube is None else tube / MM,
        farthest_at=_farthest_at(problem, state["position_rad"][judged]),
        time_s=state["time_s"],
        angles_rad=state["position_rad"],
        followed=followed_in_log(table, state),
    )


FEED_RESOLUTION = 0.05
"""How finely :func:`highest_feed_inside` finds the feed, a fraction of the planned pace."""


def highest_feed_inside(
    problem: Problem,
    trajectory: Trajectory,
    robot: Robot | None = None,
    settings: ExecutionSettings | None = None,
    progress: Callable[[float, PredictedCut], None] | None = None,
) -> tuple[float, PredictedCut] | None:
    """The highest feed, from :data:`~spm_opt.execution.feed.FEED_STEP` to ``settings``'
    starting feed and within :data:`FEED_RESOLUTION`, at which the predicted cut stays in
    the tube, with its prediction, by bisection (None if the lowest feed leaves it too);
    ``progress`` is told each feed tried and its prediction. Bisection takes the cut's
    distance to grow with the feed, which a plant's stick-slip at low speeds can break:
    the feed found is predicted inside, higher ones tried were not."""
    settings = settings or ExecutionSettings()

    def tried(feed: float) -> PredictedCut:
        predicted = predict_cut(
            problem, trajectory, robot, dataclasses.replace(settings, feed=feed)
        )
        if progress is not None:
            progress(feed, predicted)
        return predicted

    high = settings.feed
    first = tried(high)
    if first.inside:
        return high, first
    low, best = FEED_STEP, None
    while high - low > FEED_RESOLUTION:
        middle = round(0.5 * (low + high) / FEED_RESOLUTION) * FEED_RESOLUTION
        if not low < middle < high:
            break
        predicted = tried(middle)
        if predicted.inside:
            low, best = middle, predicted
        else:
            high = middle
    if best is None:
        lowest = tried(FEED_STEP)
        return (FEED_STEP, lowest) if lowest.inside else None
    return low, best


def past_margin(shares: dict[str, float]) -> list[tuple[str, float]]:
    """Of a report's ``limit_shares`` ("theta2 jerk": 0.96), those past their share of the
    limit (:data:`LIMIT_SHARES`), the largest over its margin first."""
    past = [(name, share) for name, share in shares.items() if share > _margin(name)]
    return sorted(past, key=lambda item: -item[1] / _margin(item[0]))


def worst_by_figure(shares: dict[str, float]) -> dict[str, float]:
    """Of a report's ``limit_shares``, the worst over the joints of each figure ("theta2
    jerk": 0.9 → "jerk": 0.9)."""
    worst: dict[str, float] = {}
    for name, share in shares.items():
        figure = _figure(name)
        worst[figure] = max(worst.get(figure, 0.0), share)
    return worst


def _figure(name: str) -> str:
    """The figure a limit share is of: "theta1 jerk" → "jerk"."""
    return name.split()[-1]


def _margin(name: str) -> float:
    """The share of the limit :data:`LIMIT_SHARES` keeps for the figure ``name`` ("theta1
    jerk")."""
    return LIMIT_SHARES[_figure(name)]


def _farthest_at(problem: Problem, angles: np.ndarray) -> str:
    """Where along the contour the cut of the joint ``angles`` (N, 2), rad, lies farthest
    from it: "the cut from A2 to A3, about 12.3 mm along it"."""
    contour = problem.contour
    directions = kinematics.motion_directions(angles, np.zeros_like(angles))[0]
    worst = int(np.argmax(contour.deviation(directions)))
    near = contour.nearest(directions[worst : worst + 1])
    arc = int(near.arc[0])
    along = float(contour.arc_length(near)[0] - contour.landmark_arc_lengths[arc])
    return stretch(problem.visit_names, arc, along)


@contextmanager
def _quiet(logger: logging.Logger) -> Iterator[None]:
    """Hold back ``logger``'s records below errors: the model's run is not the robot's."""
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)
