"""How the executor runs a plan: its settings, checked when made (SI)."""

from __future__ import annotations

from dataclasses import dataclass

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt
from spm_opt.execution.feed import FEED_STEP, JointLimits
from spm_opt.execution.tracking import TRACKING_MODES
from spm_opt.model.params import DEG
from spm_opt.problem.problem import Problem


@dataclass(frozen=True)
class ExecutionSettings:
    """How the executor runs a plan (SI).

    Attributes
    ----------
    rate_hz : float, Hz
        Control loop rate.
    start_tolerance_rad : float, rad
        Largest distance of the robot from the plan's start at which the plan may begin.
    approach : bool
        Move to the plan's start first (a ruckig move from rest to rest) when farther.
    approach_speed_rad_s : float, rad/s
        Speed limit of the approach move.
    tracking : str
        "lead": each goal leads the reference by the position loop's expected lag (see
        :mod:`spm_opt.execution.tracking`); "none": the goal is the reference.
    min_following_error_rad, max_following_error_rad : float, rad
        Largest distance allowed between a joint's measured position and its reference
        (the plan at the logged plan time): ``min`` at rest, growing in proportion to
        the reference's speed to ``max`` at the problem's joint speed limit (``None``:
        1° with the lead, 6° without). Measured with the plant ``prototype_plant.toml``
        (heavier than the planning model, with drive friction and rotor inertia) on
        every planner's plan of ``craniotomy_hardware.toml`` (up to the 1.43 rad/s
        speed limit): with the lead the measured error peaks at 0.05–0.17° on the
        simulated robot and 0.05–0.28° through the SDK and the emulator; without it,
        the loop's lag reaches 2.8–3.2° per rad/s of the reference's speed (q̇ (1/Kp +
        T/2) and the acceleration's share), 2.9° at the speed limit. 1° is 3.5 times
        the largest led error; 6° at the limit is 1.3 times the unled lag's worst
        ratio. A joint stuck at full speed passes 1° in 12 ms (1.2 control periods).
    communication_retries : int
        Consecutive control cycles with a failed read or a failed write tolerated before
        the run stops.
    stop_acceleration_rad_s2, stop_jerk_rad_s3 : float
        Limits of the stop and of the approach (defaults when the problem has none).
    settle_s : float, s
        At the plan's start and after its end, longest time allowed for the joints to come
        to rest.
    rest_speed_rad_s : float, rad/s
        Measured joint speed below which a sample counts as at rest.
    rest_window_s : float, s
        Rest is confirmed by samples covering this long, every one slower than
        ``rest_speed_rad_s``, over which each joint's measured position spans fewer than
        ``rest_position_pulses`` encoder pulses (at the plan's start, every one also fewer
        than that from the start).
    rest_position_pulses : int
        See ``rest_window_s`` (pulses of the actuator's encoder: 5 of the L54's 361,384
        per revolution are 0.005°).
    hold_s : float, s
        After a stop, longest time spent holding to confirm rest.
    flush_interval_s : float, s
        Longest time a sample waits before it is written to the log.
    current_reads_per_cycle : int
        Present Current reads while a goal is held, one at a random instant in each of as
        many equal parts of the hold (0 to 20); the log holds their mean instead of the
        cycle's own read,
        which, made at the same instant of every period, aliases the velocity loop's
        answer to each goal step (:mod:`spm_opt.execution.cycle`). Each read is one more
        bus transaction: 0 (the default) leaves the loop's timing as it is.
    log_stall_s : float, s
        A write to the log that has not returned after this long is a fault, as one that
        failed is: the run stops safely (the stop never waits on the disk).
    feed : float
        The feed override the plan starts at, a fraction of its planned pace: from
        :data:`~spm_opt.execution.feed.FEED_STEP` (0.1, the lowest the keys set) to 4. A
        run cannot start held (a feed of 0 would hold at the start until ``max_hold_s``
        ends it in the safe stop); a hold during the run (``Executor.hold``, or
        ``Executor.set_feed(0)``) is another matter.
    max_feed : float
        Highest override allowed, if every limit allows it (see
        :func:`~spm_opt.execution.ceiling.feed_ceiling`).
    max_hold_s : float, s
        Longest feed hold; a longer one ends in the safe stop.
    other_problem : bool
        Run a plan made for another problem, or one that records none, under this
        problem's limits (see :mod:`spm_opt.execution.preflight`).
    """

    rate_hz: float = 100.0
    start_tolerance_rad: float = 0.25 * DEG
    approach: bool = False
    approach_speed_rad_s: float = 0.1
    tracking: str = "lead"
    min_following_error_rad: float = 0.25 * DEG
    max_following_error_rad: float | None = None
    communication_retries: int = 3
    stop_acceleration_rad_s2: float = 1.0
    stop_jerk_rad_s3: float = 10.0
    settle_s: float = 1.0
    rest_speed_rad_s: float = 0.005
    rest_window_s: float = 0.2
    rest_position_pulses: int = 5
    hold_s: float = 1.0
    flush_interval_s: float = 0.1
    current_reads_per_cycle: int = 0
    log_stall_s: float = 1.0
    feed: float = 1.0
    max_feed: float = 1.5
    max_hold_s: float = 600.0
    other_problem: bool = False

    def __post_init__(self) -> None:
        checks = {
            "rate_hz": (1.0, 2000.0),
            "start_tolerance_rad": (1e-6, 0.5),
            "approach_speed_rad_s": (1e-3, 2.0),
            "min_following_error_rad": (1e-5, 1.0),
            "communication_retries": (0, 1000),
            "stop_acceleration_rad_s2": (1e-3, 100.0),
            "stop_jerk_rad_s3": (1e-3, 10000.0),
            "settle_s": (0.0, 60.0),
            "rest_speed_rad_s": (1e-6, 1.0),
            "rest_window_s": (0.0, 10.0),
            "rest_position_pulses": (1, 100_000),
            "hold_s": (0.0, 60.0),
            "flush_interval_s": (1e-3, 0.1),
            "current_reads_per_cycle": (0, 20),
            "log_stall_s": (0.05, 60.0),
            "feed": (FEED_STEP, 4.0),
            "max_feed": (1.0, 4.0),
            "max_hold_s": (0.0, 86_400.0),
        }
        if self.max_following_error_rad is not None:
            checks["max_following_error_rad"] = (0.0, 1.0)
        for name, (low, high) in checks.items():
            value = getattr(self, name)
            if not (isinstance(value, int | float) and low <= value <= high):
                raise InputError(f"{name} = {excerpt(value)}: expected a number in [{low}, {high}]")
        for name in ("communication_retries", "rest_position_pulses", "current_reads_per_cycle"):
            if not isinstance(getattr(self, name), int):
                raise InputError(f"{name} = {excerpt(getattr(self, name))}: expected an integer")
        for name in ("approach", "other_problem"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"{name} = {excerpt(getattr(self, name))}: expected true or false")
        if self.tracking not in TRACKING_MODES:
            raise InputError(
                f"tracking = {excerpt(self.tracking)}: expected one of {', '.join(TRACKING_MODES)}"
            )
        if self.feed > self.max_feed:
            raise InputError(
                f"feed = {excerpt(self.feed)}: expected at most max_feed ({excerpt(self.max_feed)})"
            )
        for name in ("settle_s", "hold_s"):
            if getattr(self, name) < self.rest_window_s:
                raise InputError(
                    f"{name} = {excerpt(getattr(self, name))}: expected at least rest_window_s "
                    f"({excerpt(self.rest_window_s)} s), or rest could never be confirmed"
                )

    @property
    def following_error_bounds(self) -> tuple[float, float]:
        """(at rest, at the speed limit), rad: see ``min_following_error_rad``."""
        most = self.max_following_error_rad
        if most is None:
            most = (1.0 if self.tracking == "lead" else 6.0) * DEG
        return self.min_following_error_rad, max(most, self.min_following_error_rad)

    def joint_limits(self, problem: Problem) -> JointLimits:
        """The limits every commanded motion keeps (the plan at any feed, the approach, the
        stop): the problem's, with the stop's acceleration and jerk where it sets none."""
        limits = problem.limits
        return JointLimits(
            limits.max_joint_speed,
            limits.max_joint_acceleration or self.stop_acceleration_rad_s2,
            limits.max_joint_jerk or self.stop_jerk_rad_s3,
        )
