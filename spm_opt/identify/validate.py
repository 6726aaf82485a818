"""An identification checked: a held-out stretch of each log, the torque predictions of a
robot on logs, and a known plant's true base parameters.

The held-out stretch (:func:`hold_out`) is the last share of each log, kept out of the fit:
its samples are filtered on their own, so no fitted row sees its torques. Where the log's
plan is periodic (an excitation's header records its period), the stretch is that many
whole periods counted back from the plan's end, with what the log holds after the plan.

The prediction error is measured as the fit sees the torques: both the measured torques
and the model's through the samples' parallel filter (:mod:`spm_opt.identify.samples`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.execution.log import header_path
from spm_opt.identify.samples import MIN_RUN_SAMPLES, Samples
from spm_opt.model import dynamics
from spm_opt.model.base_parameters import SAMPLES, base_parameters, random_states
from spm_opt.model.params import Robot
from spm_opt.model.regressor import regressor

MAX_HOLDOUT = 0.5
"""The largest share of each log ``--holdout`` keeps out of the fit."""
TRUTH_RESIDUAL = 1e-9
"""Largest residual, relative to the largest torque, of a plant's torques in a prior's base
parameters (:func:`true_base_parameters`): above it the two robots differ in structure."""


def check_holdout(fraction: float) -> None:
    """Refuse a held-out share outside [0, :data:`MAX_HOLDOUT`]."""
    if not 0.0 <= fraction <= MAX_HOLDOUT:
        raise InputError(
            f"--holdout {fraction:g}: expected the share of each log kept out of the fit, "
            f"from 0 to {MAX_HOLDOUT:g}"
        )


def plan_period(path: Path) -> tuple[float, float] | None:
    """The period and duration (s) of the periodic plan a log ran, from its JSON header
    (an excitation's ``plan.excitation.period_s`` and ``plan_duration_s``), or None."""
    header = header_path(Path(path))
    if not header.is_file():
        return None
    try:
        recorded = json.loads(header.read_text(encoding="utf-8"))
        period = float(recorded["plan"]["excitation"]["period_s"])
        duration = float(recorded["plan_duration_s"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        return None
    return (period, duration) if 0.0 < period <= duration else None


def hold_out(
    samples: Samples, fraction: float, period: tuple[float, float] | None = None
) -> tuple[Samples, Samples | None]:
    """One log's samples split into those fitted and the held-out stretch (None when
    ``fraction`` is 0 or leaves fewer than a run's minimum of samples): the last
    ``fraction`` of its seconds, or, with the plan's ``period`` (period and duration, s,
    :func:`plan_period`), the nearest whole number of periods (at least one) counted back
    from the plan's end (the log's end less what it holds after the plan)."""
    check_holdout(fraction)
    total = samples.duration_s
    held_s = fraction * total
    if period is not None and fraction > 0.0:
        period_s, plan_s = period
        held_s = max(1, round(fraction * plan_s / period_s)) * period_s + max(0.0, total - plan_s)
    fitted, held, left = [], [], held_s
    for run, rate in reversed(list(zip(samples.runs, samples.rates_hz, strict=True))):
        length = run.stop - run.start
        count = min(length, int(round(left * rate)))
        left -= count / rate
        if count < MIN_RUN_SAMPLES:
            count = 0
        elif length - count < MIN_RUN_SAMPLES:
            count = length
        cut = run.stop - count
        if cut > run.start:
            fitted.insert(0, (slice(run.start, cut), rate))
        if count:
            held.insert(0, (slice(cut, run.stop), rate))
    if not held or not fitted:
        return samples, None
    return subset(samples, fitted), subset(samples, held)


def subset(samples: Samples, runs: list[tuple[slice, float]]) -> Samples:
    """The samples of ``runs`` (slices into ``samples``' rows, each with its rate, Hz), each
    a run of its own."""
    rows = np.concatenate([np.arange(run.start, run.stop) for run, _ in runs])
    starts = np.cumsum([0] + [run.stop - run.start for run, _ in runs])
    return dataclasses.replace(
        samples,
        q=samples.q[rows],
        qd=samples.qd[rows],
        qdd=samples.qdd[rows],
        torque=samples.torque[rows],
        sides=None if samples.sides is None else samples.sides[rows],
        runs=[slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:], strict=True)],
        rates_hz=[rate for _, rate in runs],
    )


def joined(parts: list[Samples]) -> Samples:
    """The samples of several logs (same filter settings) as one (the torques' sides only
    if every part has them)."""
    first = parts[0]
    offsets = np.cumsum([0] + [len(part.q) for part in parts])
    sides = [part.sides for part in parts]
    return dataclasses.replace(
        first,
        **{
            name: np.concatenate([getattr(part, name) for part in parts])
            for name in ("q", "qd", "qdd", "torque")
        },
        sides=None if any(side is None for side in sides) else np.concatenate(sides),
        runs=[
            slice(run.start + int(offset), run.stop + int(offset))
            for part, offset in zip(parts, offsets, strict=False)
            for run in part.runs
        ],
        rates_hz=[rate for part in parts for rate in part.rates_hz],
    )


def filtered_prediction(robot: Robot, samples: Samples) -> np.ndarray:
    """The model's actuator torques of ``robot`` at the samples' motion, through the
    parallel filter (M, 2), N·m."""
    return samples.parallel(dynamics.actuator_torque(robot, samples.q, samples.qd, samples.qdd))


def prediction_rms(robot: Robot, samples: Samples) -> np.ndarray:
    """RMS of measured − predicted torque per joint (2,), N·m, both through the parallel
    filter (:func:`filtered_prediction`). Where the samples hold the torques' sides and the
    robot's gear train loses, as identification measures it: the measured torque at the
    joints (:meth:`~spm_opt.identify.samples.Samples.joint_torque`, at the robot's η) less
    the model's, in motor torque (over the share η or 1 / η the model's torque gives)."""
    efficiency = robot.actuator.gear_efficiency
    if samples.sides is None or efficiency == 1.0:
        error = samples.parallel(samples.torque) - filtered_prediction(robot, samples)
    else:
        lossless = dataclasses.replace(
            robot, actuator=dataclasses.replace(robot.actuator, gear_efficiency=1.0)
        )
        joint = dynamics.actuator_torque(lossless, samples.q, samples.qd, samples.qdd)
        error = samples.parallel(samples.motor_error(joint * samples.qd > 0.0, efficiency, joint))
    return np.sqrt(np.mean(error**2, axis=0))


def true_base_parameters(prior: Robot, plant: Robot) -> np.ndarray:
    """β (r,) of ``plant`` in ``prior``'s base parameters: least squares of the prior's
    base columns against the plant's torques at the joints (its model torques with a
    lossless gear train, less the prior's payload torque, as
    :func:`~spm_opt.identify.estimate.identify` fits) over random states. The robots may
    differ in lengths, payload and gravity (measured: a mass centre's or a rail's radius,
    the payload's mass, gravity leave the torques linear in the prior's base parameters);
    an error if they leave a residual above round-off."""
    base = base_parameters(prior)
    q, qd, qdd = random_states(prior, SAMPLES, seed=1)
    y, payload = regressor(prior, q, qd, qdd)
    actuator = dataclasses.replace(plant.actuator, gear_efficiency=1.0)
    torque = dynamics.actuator_torque(dataclasses.replace(plant, actuator=actuator), q, qd, qdd)
    a, b = base.columns(y).reshape(-1, base.rank), (torque - payload).reshape(-1)
    beta, *_ = np.linalg.lstsq(a, b, rcond=None)
    residual = float(np.max(np.abs(a @ beta - b)))
    if residual > TRUTH_RESIDUAL * float(np.max(np.abs(b))):
        raise InputError(
            f"plant robot {plant.name}: its torques are not linear in the base parameters of "
            f"{prior.name} (residual {residual:.3g} N·m); the robots differ in structure"
        )
    return beta
