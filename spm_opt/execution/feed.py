"""The pace along a plan: feed hold, resume and override that keep the tool on the path.

The executor follows a plan q(τ) through its own time parameter τ, advanced at the feed
r = dτ/dt (1: as planned). The goal it sends is q(τ); its rate is q′ r, its acceleration
q″ r² + q′ ṙ and its jerk q‴ r³ + 3 q″ r ṙ + q′ r̈ (primes: derivatives of the plan in τ).
Only the pace changes, so the goal never leaves the planned path: a feed of 0 holds the
tool on the contour, and any feed above 0 goes on from the same point.

The feed moves to a new target along a jerk-limited profile: ruckig on the one coordinate
τ through its velocity interface (its velocity is r, its acceleration ṙ, its jerk r̈),
computed locally, without waypoints. Its bounds on ṙ and r̈ come from the plan's
derivatives over the stretch of plan time the change will cover (found by widening the
stretch until the profile stays inside it), with r between its start and its target:

- acceleration: |q″ r² + q′ ṙ| ≤ A gives ṙ ≤ (A − sign(q′ ṙ) q″ r²) / |q′| at each sample;
- jerk: |q‴| r³ + 3 |q″| r |ṙ| + |q′| |r̈| ≤ J gives r̈ once ṙ's bound is chosen (ṙ's
  bound is halved while that shortens the change);
- speed: r never exceeds the larger of its start and its target, so |q′ r| stays within
  what the plan at that feed needs, which the ceiling
  (:func:`~spm_opt.execution.ceiling.feed_ceiling`) keeps within the speed limit.

The bounds use :data:`HEADROOM` of each limit. Every profile is then checked before it is
used, at samples half a control period apart: the joints' speed, acceleration and jerk
(signed, with r̈ on either side of each sample) within the limits as the evaluator allows
them (:mod:`spm_opt.judge.limits`), or within what the plan itself needs at that feed where that
is more (the ceiling's business), and r ≥ 0.

Where that finds no room (a time-optimal plan braking at its acceleration limit leaves none
to brake harder, and its window's bounds count every term at its worst):

- a hold takes a reference stop of :mod:`spm_opt.judge.hold_room` (r to 0 with |ṙ| ≤ R and
  |r̈| ≤ Q), the quickest that fits of those within :data:`HOLD_SHARES` of the problem's
  ``hold_within_s``, checked the same way, where it is quicker than the change above or
  that one does not fit. Every plan the evaluator passes leaves the whole bound's stop
  room from any steady feed up to 1 (the planners keep it); above 1, its bounds scale with
  the feed (the stop of the plan run that much faster, whose room the ceiling keeps,
  :func:`~spm_opt.execution.ceiling.feed_ceiling`), so it lasts no longer. With none that
  fits, :class:`NoRoom`: the executor ends the run in the safe stop at once, never waiting;
- a higher feed (a resume) goes in stages: the highest of :data:`STAGES` of it that fits
  now, and the whole of it, tried again each cycle, as soon as the plan gives room (a plan
  at its acceleration or jerk limit leaves room at 90 % of its pace);
- a lower feed that is not a hold waits and is tried again the next cycle; the goal goes on
  as before.

A new target other than a hold waits for a change under way (a stop, a stage) to end; a
hold is tried at once, from wherever the feed is.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
import ruckig

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt
from spm_opt.base.ruckig_local import calculate_locally
from spm_opt.judge.hold_room import hold_stop
from spm_opt.judge.limits import RULES
from spm_opt.problem.trajectory import Trajectory

HEADROOM = 0.98
"""Fraction of each joint limit the feed's bounds on ṙ and r̈ are derived for; the rest
covers the motion between the samples they are derived at."""

MAX_FEED_RATE_PER_S = 20.0
"""Fastest change of the feed, 1/s, where the plan barely moves (q′ ≈ 0 gives no bound):
a hold from full feed then takes at least 50 ms."""

MAX_FEED_JERK_PER_S2 = 400.0
"""Largest r̈, 1/s², where the plan gives no bound."""

FEED_STEP = 0.1
"""The override's step from the keys, and its lowest value from them (a fraction)."""

LONGEST_CHANGE_S = 2.0
"""Longest change of the feed tried, s: a longer one (its bounds shrunk far) costs its check
more than it is worth; the change waits, or goes in stages, instead."""

STAGES = (0.9, 0.7, 0.5, 0.3, 0.1)
"""Fractions of a higher feed tried, highest first, when the whole of it finds no room."""

HOLD_SHARES = (0.25, 0.5, 1.0)
"""Shares of the hold bound the reference stop is tried within, quickest first: where the
plan leaves more room than the bound needs, the hold stops sooner."""

_ATTEMPTS = 8
_WINDOW_SAMPLES = 200
_FIRST_SPAN_S = 0.05
_TINY = 1e-12


class NoRoom(Exception):
    """No path-keeping stop fits the limits now: a hold must be the safe stop."""


@dataclass(frozen=True)
class JointLimits:
    """The limits every commanded joint motion keeps: rad/s, rad/s², rad/s³."""

    speed: float
    acceleration: float
    jerk: float


@dataclass(frozen=True)
class Pace:
    """Where the executor is along the plan.

    Attributes
    ----------
    plan_time_s : float, s
        τ, the plan's time since its start.
    feed : float
        r = dτ/dt (1: as planned, 0: held).
    feed_rate_per_s : float, 1/s
        ṙ.
    target : float
        The feed r is moving to.
    """

    plan_time_s: float
    feed: float
    feed_rate_per_s: float
    target: float


class FeedProfile:
    """The pace along one plan: τ, r and ṙ at any time of the plan phase.

    Parameters
    ----------
    trajectory : Trajectory
    limits : JointLimits
    feed : float
        The feed at the plan's start (the plan starts at rest, so it may start at any).
    sample_s : float, s
        Spacing of the samples a profile is checked at (half the control period).
    hold_within_s : float or None, s
        The problem's hold bound, which the reference stops a hold falls back on keep
        (None: the problem sets none).
    """

    def __init__(
        self,
        trajectory: Trajectory,
        limits: JointLimits,
        feed: float,
        sample_s: float,
        hold_within_s: float | None,
    ) -> None:
        self._trajectory = trajectory
        self._start = trajectory.start_time
        self.duration = trajectory.duration
        self._limits = limits
        self._allowed = (
            RULES["joint speed"].allowed(limits.speed),
            RULES["joint acceleration"].allowed(limits.acceleration),
            RULES["joint jerk"].allowed(limits.jerk),
        )
        self._sample_s = sample_s
        within = [] if hold_within_s is None else [hold_within_s * s for s in HOLD_SHARES]
        self._stops = [hold_stop(time) for time in within]
        feed = max(feed, 0.0)
        self._origin_s, self._origin = 0.0, (0.0, feed, 0.0)
        self._motion: ruckig.Trajectory | None = None
        self._end = self._origin
        self._target = feed

    def advance(self, time_s: float, target: float) -> Pace:
        """The pace at ``time_s`` (s since the plan phase began), heading for ``target``
        (≥ 0; at most the plan's ceiling, which :class:`FeedRequests` keeps) if a
        jerk-limited change to it fits the limits now, or to a stage of a higher target
        (see the module docstring).

        Raises
        ------
        NoRoom
            When ``target`` is 0 (a hold) and no path-keeping stop fits.
        """
        target = max(target, 0.0)
        if target != self._target and (target == 0.0 or self._steady(time_s)):
            state = self._state(time_s)
            if target == 0.0:
                goal, motion = 0.0, self._stop(state)
            else:
                goal, motion = self._towards(state, target)
            if motion is not False:
                self._origin_s, self._origin, self._target = time_s, state, goal
                self._motion = motion
                tau = state[0] if motion is None else _end_tau(motion)
                self._end = (tau, goal, 0.0)
        tau, feed, rate = self._state(time_s)
        return Pace(min(tau, self.duration), feed, rate, self._target)

    def finished(self, pace: Pace) -> bool:
        """The plan's end is reached."""
        return pace.plan_time_s >= self.duration

    def goal(self, pace: Pace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Goal position, rate and acceleration (each (2,), SI) at ``pace``."""
        t = self._start + pace.plan_time_s
        trajectory = self._trajectory
        position = trajectory.position(t)
        velocity = trajectory.velocity(t)
        acceleration = trajectory.acceleration(t)
        return (
            position,
            velocity * pace.feed,
            acceleration * pace.feed**2 + velocity * pace.feed_rate_per_s,
        )

    # ------------------------------------------------------------------ internals
    def _steady(self, time_s: float) -> bool:
        """No change of the feed is under way at ``time_s``: a new target other than a hold
        waits for the change under way (a stop, a stage) to end before it is tried."""
        motion = self._motion
        return motion is None or time_s - self._origin_s >= motion.duration

    def _state(self, time_s: float) -> tuple[float, float, float]:
        """(τ, r, ṙ) at ``time_s`` on the current profile, then at its final feed."""
        elapsed = time_s - self._origin_s
        motion = self._motion
        if motion is not None and elapsed < motion.duration:
            tau, feed, rate = (values[0] for values in motion.at_time(elapsed))
            return tau, max(feed, 0.0), rate
        since = elapsed - (motion.duration if motion is not None else 0.0)
        tau, feed, _ = self._end
        return tau + feed * since, feed, 0.0

    def _stop(self, state: tuple[float, float, float]) -> ruckig.Trajectory | None:
        """The quickest stop that fits: the checked change to 0, or a reference stop
        (quickest first) where that is quicker; None when the feed is already at rest;
        raises :class:`NoRoom` when none fits."""
        best = self._change(state, 0.0)
        if best is None:
            return None
        _, feed, rate = state
        faster = max(feed, 1.0)  # above 100 %: the reference stop of the plan run faster
        for stop in self._stops:
            if best is not False and best.duration <= stop.duration_s:
                break
            rate_bound, jerk_bound = faster * stop.rate_per_s, faster * stop.jerk_per_s2
            motion = _profile(state, 0.0, rate_bound, jerk_bound)
            overshoot = max(rate, 0.0) ** 2 / (2.0 * jerk_bound)
            if self._keeps_limits(motion, feed + overshoot):
                best = motion
                break
        if best is False:
            tau, feed, _ = state
            raise NoRoom(f"no path-keeping stop fits at plan time {tau:.3f} s, feed {feed:.0%}")
        return best

    def _towards(
        self, state: tuple[float, float, float], target: float
    ) -> tuple[float, ruckig.Trajectory | None | bool]:
        """(the feed headed for, its checked profile) towards ``target`` > 0: the whole
        change, or for a higher feed the highest stage of it above both the feed and the
        feed already headed for that fits; False as the profile when none does."""
        motion = self._change(state, target)
        if motion is not False or target < state[1]:
            return target, motion
        for stage in (fraction * target for fraction in STAGES):
            if stage <= max(state[1], self._target):
                break
            motion = self._change(state, stage)
            if motion is not False:
                return stage, motion
        return self._target, False

    def _change(
        self, state: tuple[float, float, float], target: float
    ) -> ruckig.Trajectory | None | bool:
        """A checked profile from ``state`` to ``target``; None when no profile is needed
        (already there, at rest), False when none fits the limits now."""
        tau, feed, rate = state
        if abs(feed - target) < _TINY and abs(rate) < _TINY:
            return None
        if tau >= self.duration:
            return None
        direction = 1.0 if target > feed or (target == feed and rate < 0.0) else -1.0
        low, high = min(feed, target), max(feed, target)
        span, shrink = max(high, _TINY) * _FIRST_SPAN_S, 1.0
        for _ in range(_ATTEMPTS):
            derivatives = self._derivatives(np.linspace(tau, tau + span, _WINDOW_SAMPLES))
            rate_bound, jerk_bound = self._bounds(*derivatives, low, high, direction)
            if rate_bound <= 0.0 or jerk_bound <= 0.0:
                return False
            motion = _profile(state, target, shrink * rate_bound, shrink * jerk_bound)
            if motion.duration > LONGEST_CHANGE_S:  # shrinking would only lengthen it
                return False
            covered = _end_tau(motion) - tau
            if covered > span and tau + span < self.duration:
                span = 1.5 * covered
                continue
            if self._keeps_limits(motion, max(high, feed)):
                return motion
            shrink *= 0.5
        return False

    def _derivatives(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q′, q″, q‴ at plan times τ (N,), each (N, 2); zero past the plan's end."""
        _, velocity, acceleration, jerk = self._trajectory.states(self._start + tau)
        return velocity, acceleration, jerk

    def _bounds(
        self,
        q1: np.ndarray,
        q2: np.ndarray,
        q3: np.ndarray,
        low: float,
        high: float,
        direction: float,
    ) -> tuple[float, float]:
        """Bounds on |ṙ| and |r̈| (1/s, 1/s²) over samples of the plan's derivatives, for a
        feed between ``low`` and ``high`` changing in ``direction`` (±1)."""
        acceleration = HEADROOM * self._limits.acceleration
        jerk = HEADROOM * self._limits.jerk
        c = direction * q1
        moving = np.abs(c) > _TINY
        rate_bound = MAX_FEED_RATE_PER_S
        for feed in (low, high):
            room = acceleration - np.sign(c) * q2 * feed**2
            if np.any(room[moving] <= 0.0):
                return 0.0, 0.0
            if np.any(moving):
                rate_bound = min(rate_bound, float(np.min(room[moving] / np.abs(c[moving]))))
        best, best_time = (0.0, 0.0), math.inf
        change = max(high - low, _TINY)
        for halving in range(7):
            rate = rate_bound / 2**halving
            room = jerk - np.abs(q3) * high**3 - 3.0 * np.abs(q2) * high * rate
            if np.any(room[moving] <= 0.0):
                continue
            jerk_bound = MAX_FEED_JERK_PER_S2
            if np.any(moving):
                ratio = room[moving] / np.abs(q1[moving])
                jerk_bound = min(jerk_bound, float(np.min(ratio)))
            duration = change / rate + rate / jerk_bound
            if duration < best_time:
                best, best_time = (rate, jerk_bound), duration
        return best

    def _keeps_limits(self, motion: ruckig.Trajectory, most_feed: float) -> bool:
        """The profile's commanded joint motion, at samples ``sample_s`` apart, within the
        limits (or the plan's own needs at that feed), with 0 ≤ r ≤ ``most_feed``."""
        end = self._time_to_reach(motion, self.duration)
        times = np.append(np.arange(0.0, end, self._sample_s), end)
        states = np.array([[v[0] for v in motion.at_time(t)] for t in times])
        tau, feed, rate = states.T
        if np.any(feed < -1e-9) or np.any(feed > most_feed + 1e-9):
            return False
        steps = np.diff(rate) / np.maximum(np.diff(times), _TINY)
        q1, q2, q3 = self._derivatives(np.minimum(tau, self.duration))
        r, rd = feed[:, None], rate[:, None]
        before, after = np.append(0.0, steps)[:, None], np.append(steps, 0.0)[:, None]
        speed_limit, acceleration_limit, jerk_limit = self._allowed
        speed_ok = np.abs(q1 * r) <= speed_limit
        acceleration_ok = np.abs(q2 * r**2 + q1 * rd) <= np.maximum(
            acceleration_limit, np.abs(q2) * r**2
        )
        own = q3 * r**3 + 3.0 * q2 * r * rd
        jerk = np.maximum(np.abs(own + q1 * before), np.abs(own + q1 * after))
        jerk_ok = jerk <= np.maximum(jerk_limit, np.abs(q3) * r**3)
        return bool(np.all(speed_ok) and np.all(acceleration_ok) and np.all(jerk_ok))

    @staticmethod
    def _time_to_reach(motion: ruckig.Trajectory, tau: float) -> float:
        """When the profile's τ reaches ``tau`` (its duration if it does not): past the
        plan's end the goal rests, whatever the feed."""
        if _end_tau(motion) <= tau:
            return motion.duration
        low, high = 0.0, motion.duration
        while high - low > 1e-6 * motion.duration:
            middle = 0.5 * (low + high)
            low, high = (middle, high) if motion.at_time(middle)[0][0] < tau else (low, middle)
        return high


def _profile(
    state: tuple[float, float, float], target: float, rate_bound: float, jerk_bound: float
) -> ruckig.Trajectory:
    """Ruckig's jerk-limited change of the feed (velocity interface on τ), computed here."""
    tau, feed, rate = state
    inp = ruckig.InputParameter(1)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.current_position = [tau]
    inp.current_velocity = [feed]
    inp.current_acceleration = [rate]
    inp.target_velocity = [target]
    inp.target_acceleration = [0.0]
    inp.max_velocity = [max(feed, target, _TINY)]
    inp.max_acceleration = [rate_bound]
    inp.max_jerk = [jerk_bound]
    return calculate_locally(inp, "feed change")


def _end_tau(motion: ruckig.Trajectory) -> float:
    """τ at the profile's end, s."""
    return float(motion.at_time(motion.duration)[0][0])


class FeedRequests:
    """What the operator asks for, from any thread: a feed override, hold and resume.

    The feed the executor heads for is 0 while held, else the override, never above
    ``ceiling`` (see :func:`~spm_opt.execution.ceiling.feed_ceiling`): this is the one
    place the ceiling applies.
    """

    def __init__(self, feed: float = 1.0, ceiling: float = 1.0) -> None:
        self._lock = threading.Lock()
        self.ceiling = ceiling
        self._override = _checked_feed(feed)
        self._held = False

    def set_feed(self, fraction: float) -> float:
        """Set the override (a fraction of the planned pace, ≥ 0); returns the feed that
        applies, at most the ceiling."""
        fraction = _checked_feed(fraction)
        with self._lock:
            self._override = fraction
            return self._applied()

    def step_feed(self, step: float) -> float:
        """Change the override by ``step``, within [``FEED_STEP``, ceiling]; returns it."""
        with self._lock:
            self._override = max(round(self._applied() + step, 6), FEED_STEP)
            return self._applied()

    def hold(self) -> None:
        """Bring the tool to rest on the path."""
        with self._lock:
            self._held = True

    def resume(self) -> None:
        """Go on from where the hold stopped, at the override."""
        with self._lock:
            self._held = False

    def toggle_hold(self) -> bool:
        """Hold if running, resume if held; returns True if now held."""
        with self._lock:
            self._held = not self._held
            return self._held

    def requested(self) -> tuple[float, bool]:
        """(override, held) as they stand."""
        with self._lock:
            return self._applied(), self._held

    def _applied(self) -> float:
        """The override as it applies: at most the ceiling (the lock held)."""
        return min(self._override, self.ceiling)


def _checked_feed(fraction: float) -> float:
    if not (isinstance(fraction, int | float) and math.isfinite(fraction) and fraction >= 0.0):
        raise InputError(
            f"feed = {excerpt(fraction)}: expected a fraction of the planned pace, ≥ 0"
        )
    return float(fraction)
