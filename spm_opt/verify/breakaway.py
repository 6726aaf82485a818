"""Where the robot breaks away from rest, the plan slowed until its predicted run keeps the
robot's limits.

**Why a run breaks limits its plan keeps.** A joint at rest sticks on its Coulomb friction
(the rails' and the gear train's) until the drive's torque exceeds it. With goal positions
only, that torque comes from the position error, so the joint stays put while the goal
moves away, and breaks away once the error has reached the friction's share of the loop's
stiffness. It then has to take up the plan's velocity at that moment within the loop's
time constant: a velocity step, which the judge reads as an acceleration and a jerk far
above the plan's. It happens wherever a joint starts from rest: the plan's start, every
landmark stop, every reversal of a joint. The step is the plan's velocity when the joint
breaks free, which grows with the pace there (the plan's position after a start grows with
the pace cubed), so the broken jerk falls with the pace near those instants, not elsewhere.

:func:`slowed_for_breakaways` lowers the pace around those instants only
(:func:`~spm_opt.problem.retiming.slowed_near`) to the highest feed, within
:data:`FEED_RESOLUTION`, at which the predicted run keeps every robot limit the plan keeps,
the joints' with their margins (:func:`~spm_opt.verify.predicted_cut.predict_cut`,
:attr:`~spm_opt.verify.predicted_cut.PredictedCut.keeps_limits`), and the slowed plan is as
clean as the plan by :func:`~spm_opt.judge.evaluate.evaluate`. Bisection takes the broken
jerk to fall with the feed. A uniform feed low enough for the same would slow the whole
plan: it does so only where no dip keeps the limits.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from spm_opt.execution import ExecutionSettings
from spm_opt.judge.evaluate import evaluate
from spm_opt.model.params import Robot
from spm_opt.problem.problem import Problem
from spm_opt.problem.retiming import breakaway_times, slowed_near
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.predicted_cut import PredictedCut, predict_cut

HALF_WIDTH_S = 1.5
"""How long (plan time, s) on each side of a breakaway the pace is lowered."""
FEED_FLOOR = 0.1
"""The lowest pace tried at a breakaway, a fraction of the plan's."""
FEED_RESOLUTION = 0.05
"""How finely the pace at the breakaways is found."""


@dataclasses.dataclass(frozen=True)
class Slowed:
    """A plan slowed at its breakaways: the pace there (1: not slowed), the plan and its
    prediction."""

    feed: float
    trajectory: Trajectory
    predicted: PredictedCut

    @property
    def where(self) -> str:
        """Where the plan is slowed: "throughout" (the whole plan at the pace) or "at the
        breakaways"."""
        uniform = self.trajectory.metadata.get("slowed", {}).get("uniform", False)
        return "throughout" if uniform else "at the breakaways"

    @property
    def keeps_limits(self) -> bool:
        """Whether the predicted run completes and keeps every robot limit, with the joint
        limits' margins (:data:`~spm_opt.verify.predicted_cut.LIMIT_SHARES`)."""
        return self.predicted.keeps_limits


def slowed_for_breakaways(
    problem: Problem,
    trajectory: Trajectory,
    robot: Robot | None = None,
    settings: ExecutionSettings | None = None,
    progress: Callable[[Slowed], None] | None = None,
    half_width_s: float = HALF_WIDTH_S,
) -> Slowed:
    """The plan, or the plan slowed around its breakaways to the highest pace (from
    :data:`FEED_FLOOR` to 1, within :data:`FEED_RESOLUTION`) whose predicted run on
    ``robot`` (default: the problem's) completes and keeps every robot limit (the joints'
    with their margins), the slowed plan itself breaking no rule the plan keeps (a deep,
    short dip can break the plan's own acceleration or jerk limits, a shallow one the
    run's), with its prediction. Where no dip does (a short plan at its speed and
    acceleration limits, whose dips overlap), the whole plan at the highest uniform pace
    that does (every rate of the plan falls with it). If neither does, the slowest clean
    dip tried, or the plan itself. ``progress`` is told each slowed plan predicted."""
    times = breakaway_times(trajectory)
    allowed = {v.rule for v in evaluate(problem, trajectory).violations}

    def predicted(feed: float, slowed: Trajectory) -> Slowed:
        """``slowed``, at ``feed``, with its prediction."""
        result = Slowed(feed, slowed, predict_cut(problem, slowed, robot, settings))
        if progress is not None:
            progress(result)
        return result

    def dipped(feed: float) -> Slowed | None:
        """The plan slowed to ``feed`` at its breakaways and its prediction; None if the
        slowed plan breaks a rule the plan keeps."""
        slowed = slowed_near(trajectory, times, feed, half_width_s)
        if not {v.rule for v in evaluate(problem, slowed).violations} <= allowed:
            return None
        return predicted(feed, slowed)

    def uniform(feed: float) -> Slowed:
        """The whole plan at ``feed`` and its prediction."""
        return predicted(feed, _uniformly_slowed(trajectory, feed))

    unslowed = predicted(1.0, trajectory)
    if unslowed.keeps_limits:
        return unslowed
    best, fallback = _highest_pace(dipped)
    if best is None:
        best, _ = _highest_pace(uniform)
    return best or fallback or unslowed


def _uniformly_slowed(trajectory: Trajectory, feed: float) -> Trajectory:
    """``trajectory`` at ``feed`` (0 < feed ≤ 1) throughout, q̃(t) = q(t₀ + feed·(t − t₀)),
    from its own samples (times stretched, rates scaled), so that a stream built on its
    samples is as smooth as the plan's; the metadata records the pace under ``slowed``."""
    t, q, qd, qdd = trajectory.samples()
    start = trajectory.start_time
    metadata: dict[str, Any] = dict(trajectory.metadata)
    metadata.pop("samples", None)  # the slowed samples are recorded when written
    if trajectory.landmark_times is not None:
        metadata["landmark_times_s"] = (start + (trajectory.landmark_times - start) / feed).tolist()
    metadata["slowed"] = {
        "feed": float(feed),
        "uniform": True,
        "duration_before_s": trajectory.duration,
    }
    return Trajectory.from_samples(
        start + (t - start) / feed, q, qd * feed, qdd * feed**2, metadata
    )


def _highest_pace(
    tried: Callable[[float], Slowed | None],
) -> tuple[Slowed | None, Slowed | None]:
    """By bisection from :data:`FEED_FLOOR` to 1 (within :data:`FEED_RESOLUTION`), the
    highest pace ``tried`` whose predicted run keeps the robot's limits, and the slowest
    pace tried whose run does not; each None if there is none. ``tried`` gives None for a
    pace too low for the plan's own limits; the pace then rises."""
    best = fallback = None
    low, high = FEED_FLOOR, 1.0
    lowest = tried(low)
    if lowest is not None:
        if not lowest.keeps_limits:
            return None, lowest  # the slowest pace breaks them too: none will keep them
        best = lowest
    while high - low > FEED_RESOLUTION + 1e-9:
        middle = float(np.round(0.5 * (low + high) / FEED_RESOLUTION) * FEED_RESOLUTION)
        if not low < middle < high:
            break
        candidate = tried(middle)
        if candidate is None:
            low = middle  # the dip too deep for the plan's own limits
        elif candidate.keeps_limits:
            low, best = middle, candidate
        else:
            high, fallback = middle, candidate
    return best, fallback
