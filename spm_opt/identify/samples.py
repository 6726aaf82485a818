"""Execution logs made ready for identification: complete, uniform samples, and the
parallel filter.

Each log's rows with every measurement present (a failed read leaves them empty), but for
the hold at the plan's start (:func:`held_at_the_start`), are split into runs at the gaps
and each run resampled on a uniform grid (its median step). The motion is filtered without
phase (a 4th-order Butterworth filter forward and back, ``filtfilt``) at
:data:`STATE_CUTOFF_HZ`: the positions, and the rates that refer to the same instants as
the current, differentiated once more for the accelerations; the torques are the log's (the
current through the actuator's map). A current averaged over the period goes with the
period's mean rate, the positions' derivative: the logged Present Velocity, read at the
same instant of every period just before the next goal, samples the velocity loop's answer
to each goal step at one phase, as one current read does. Measured on the
simulated robot equal to its model but for 0.2 N·m·s/rad of viscous friction
(``problems/identification.toml``'s excitation shortened to 60 s, 100 Hz, 10 current reads
a period): the logged rate was 3.8 and 5.4 % below the positions' derivative, and
identification from it came out +0.0097 and +0.0129 N·m·s/rad too viscous (12 and 16
standard errors), the plant's own model predicting the filtered torques to 0.0080 and
0.0103 N·m; from the positions' derivative +0.0013 and +0.0016 (2 s.e.) and 0.0042 N·m,
the noise of the current reads. A current read once a period goes with the rate read with
it, Present Velocity. A log's current is the mean of Present Current reads at the
random instants spread over the period before each row (:mod:`spm_opt.execution.cycle`): it
refers to the middle of the period, half a period before the row's time, and is
resampled there, with its torques' two sides (the reads split into the side that drives
and the side driven back, for a gear train that loses: :meth:`Samples.joint_torque`). A
log of one read a period (none between goals: logs from before the executor read more, or
above 1 kHz) has no such delay, and at 100 Hz holds the velocity loop's ripple as a steady
error: about −0.1 N·m·s/rad × q̇ on the simulated robot.

Identification then filters the torques and every column of the regressor built at those
samples through the same low-pass filter, at ``cutoff_hz`` (Gautier's parallel
filtering, :meth:`Samples.parallel`): the regressor holds the friction's sign, which
filtering the motion first would not carry through. One sample in ``decimation`` is kept
(the filter took out what lies between them), and samples where a joint turns slower than
``min_speed_rad_s`` are left out: there friction holds rather than slides. Filtered rows'
residuals are correlated: :func:`correlation_factor` says how much that inflates a fit's
variances.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import scipy.signal

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import MAX_LOG_ROWS, excerpt, log_rows
from spm_opt.execution.log import read_execution_log

MEASURED = (
    "position_theta1_rad",
    "position_theta2_rad",
    "velocity_theta1_rad_s",
    "velocity_theta2_rad_s",
    "torque_theta1_nm",
    "torque_theta2_nm",
)
"""The log columns identification reads (with ``time_s``)."""
SIDES = (
    "torque_positive_theta1_nm",
    "torque_positive_theta2_nm",
    "torque_negative_theta1_nm",
    "torque_negative_theta2_nm",
)
"""The columns of a torque's two sides, read where the log has them and its current is a
period's mean (:attr:`Samples.sides`)."""
FILTER_ORDER = 4
STATE_CUTOFF_HZ = 10.0
"""Cutoff of the filter on the measured motion (at most 0.4 of the log's rate)."""
SAMPLES_PER_CUTOFF = 5
"""Samples kept a period of the parallel filter's cutoff by default (2.5 times its Nyquist
rate). Neighbouring rows' residuals stay correlated (a lag-1 autocorrelation of 0.65 to
0.75 measured on the simulated robot); identification's standard errors allow for it."""
DEFAULT_SAMPLING = (2.0, None, 0.02)
"""``spm-opt identify``'s defaults for :func:`log_samples`: the parallel filter's cutoff
(Hz), the decimation (None: :data:`SAMPLES_PER_CUTOFF`) and the smallest joint rate kept
(rad/s)."""
MIN_RUN_SAMPLES = 50
"""Shortest run kept (filtfilt pads 15 samples at each end at order 4)."""


@dataclass(frozen=True)
class Samples:
    """Uniform samples of one or more logs, and the parallel filter for them.

    Attributes
    ----------
    q, qd, qdd, torque : ndarray, shape (N, 2)
        Joint angles, rates and accelerations (the motion filtered at
        :data:`STATE_CUTOFF_HZ`: the rates the positions' derivative where the current
        is a period's mean), and the torques from the measured current, SI.
    runs : list of slice
        Each run's samples.
    rates_hz : list of float
        Each run's sample rate.
    cutoff_hz : float
        The parallel filter's cutoff.
    decimation : int
    min_speed_rad_s : float
    single_read_logs : tuple of str
        The logs whose current is one read a period (no reads while a goal was held):
        at 100 Hz it holds the velocity loop's ripple as a steady error.
    sides : ndarray, shape (N, 2, 2), or None
        The torques' positive (``[:, 0]``) and negative (``[:, 1]``) sides, N·m, per joint:
        the period's reads split by their neighbours' sign
        (:mod:`spm_opt.execution.torque_sides`); None unless
        every log's current is a period's mean and holds them.
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    torque: np.ndarray
    runs: list[slice]
    rates_hz: list[float]
    cutoff_hz: float
    decimation: int
    min_speed_rad_s: float
    single_read_logs: tuple[str, ...] = ()
    sides: np.ndarray | None = None

    @property
    def duration_s(self) -> float:
        """Seconds of log."""
        return float(
            sum(
                (r.stop - r.start - 1) / rate
                for r, rate in zip(self.runs, self.rates_hz, strict=True)
            )
        )

    @property
    def rows_per_period(self) -> int:
        """Rows :meth:`parallel` keeps per period of its cutoff (of the fastest run): the
        span over which its rows' noise is correlated."""
        return max(1, round(max(self.rates_hz) / (self.decimation * self.cutoff_hz)))

    def parallel(self, values: np.ndarray) -> np.ndarray:
        """``values`` (N, ...) low-passed at ``cutoff_hz`` run by run, decimated, and kept
        where both joints move (their filtered rates at least ``min_speed_rad_s``)."""
        return self._filtered(values)[self._moving]

    def _filtered(self, values: np.ndarray) -> np.ndarray:
        parts = []
        for run, rate in zip(self.runs, self.rates_hz, strict=True):
            b, a = scipy.signal.butter(FILTER_ORDER, self.cutoff_hz, fs=rate)
            parts.append(scipy.signal.filtfilt(b, a, values[run], axis=0)[:: self.decimation])
        return np.concatenate(parts)

    @cached_property
    def _moving(self) -> np.ndarray:
        return np.all(np.abs(self._filtered(self.qd)) >= self.min_speed_rad_s, axis=1)

    def __len__(self) -> int:
        """Samples the parallel filter keeps."""
        return int(np.sum(self._moving))

    def joint_torque(self, driving: np.ndarray, efficiency: float) -> np.ndarray:
        """The measured torques at the joints τ_j (N, 2), N·m, through a gear train of
        efficiency η (the motor's τ_m: :meth:`~spm_opt.model.actuator.Actuator.drive_torque`
        inverted). With :attr:`sides`: η times the side that turns the way the joint does
        (the motor driving) plus the other side over η, whatever the torque does within
        the period. Else η τ_m where the motor drives its load (``driving``, (N, 2) bool),
        τ_m / η where the load drives it back."""
        if self.sides is None:
            return self.torque * _gear_share(driving, efficiency)
        positive, negative = self.sides[:, 0], self.sides[:, 1]
        forward = self.qd > 0.0
        drives = np.where(forward, positive, negative)
        driven = np.where(forward, negative, positive)
        return efficiency * drives + driven / efficiency

    def motor_error(
        self, driving: np.ndarray, efficiency: float, model_joint_nm: np.ndarray
    ) -> np.ndarray:
        """The measured joint torques (:meth:`joint_torque`) less a model's
        ``model_joint_nm`` (N, 2), in motor torque: over the share η or 1 / η (``driving``)."""
        return (self.joint_torque(driving, efficiency) - model_joint_nm) / _gear_share(
            driving, efficiency
        )


def _gear_share(driving: np.ndarray, efficiency: float) -> np.ndarray:
    """τ_j / τ_m: η where the motor drives, 1 / η where it is driven back."""
    return np.where(driving, efficiency, 1.0 / efficiency)


def log_samples(
    paths: list[Path], cutoff_hz: float, decimation: int | None, min_speed_rad_s: float
) -> Samples:
    """The samples of the logs at ``paths`` (see the module docstring); ``decimation``
    None: :data:`SAMPLES_PER_CUTOFF` samples a period of the cutoff. Logs of more than
    :data:`~spm_opt.base.input_limits.MAX_LOG_ROWS` rows together are refused before any is
    parsed (:func:`check_log_rows`)."""
    if decimation is not None and decimation < 1:
        raise InputError(f"--decimation {decimation}: expected a whole number >= 1")
    if not min_speed_rad_s >= 0.0:
        raise InputError(f"--min-speed {min_speed_rad_s}: expected a rate >= 0 rad/s")
    check_log_rows(paths)
    runs = [run for path in paths for run in _runs(Path(path))]
    if not runs:
        raise InputError(
            f"logs {named(paths)}: no run of {MIN_RUN_SAMPLES} complete samples or more"
        )
    with_sides = all(reads and values.shape[1] > len(MEASURED) for _, _, values, reads in runs)
    parts, slices, rates, start = [], [], [], 0
    for path, t, values, reads in runs:
        rate, uniform = _uniform(path, t, values if with_sides else values[:, :6], reads)
        if not 0.0 < cutoff_hz < 0.5 * rate:
            raise InputError(
                f"--cutoff-hz {cutoff_hz:g}: must lie between 0 and half the log's rate "
                f"({0.5 * rate:g} Hz in {path.name})"
            )
        b, a = scipy.signal.butter(FILTER_ORDER, min(STATE_CUTOFF_HZ, 0.4 * rate), fs=rate)
        motion = scipy.signal.filtfilt(b, a, uniform[:, 0:4], axis=0)
        if reads:  # the period's mean rate, as the current is the period's mean
            motion[:, 2:4] = np.gradient(motion[:, 0:2], 1.0 / rate, axis=0)
        qdd = np.gradient(motion[:, 2:4], 1.0 / rate, axis=0)
        parts.append(np.hstack([motion, qdd, uniform[:, 4:]]))
        slices.append(slice(start, start + len(uniform)))
        rates.append(rate)
        start += len(uniform)
    table = np.concatenate(parts)
    if decimation is None:
        decimation = max(1, int(rates[0] / (SAMPLES_PER_CUTOFF * cutoff_hz)))
    return Samples(
        q=table[:, 0:2],
        qd=table[:, 2:4],
        qdd=table[:, 4:6],
        torque=table[:, 6:8],
        runs=slices,
        rates_hz=rates,
        cutoff_hz=cutoff_hz,
        decimation=decimation,
        min_speed_rad_s=min_speed_rad_s,
        single_read_logs=tuple(dict.fromkeys(str(path) for path, *_, reads in runs if not reads)),
        sides=table[:, 8:12].reshape(-1, 2, 2) if with_sides else None,
    )


def _runs(path: Path) -> list[tuple[Path, np.ndarray, np.ndarray, int]]:
    """(path, time (n,), measurements (n, 6, or 10 with the torques' :data:`SIDES`), current
    reads a period) of each run of complete samples."""
    table, header = read_execution_log(path)
    t = log_values(table, ("time_s",), path)[:, 0]
    columns = MEASURED + SIDES if set(SIDES) <= set(table.columns) else MEASURED
    values = log_values(table, columns, path)
    complete = np.all(np.isfinite(values), axis=1) & np.isfinite(t) & ~held_at_the_start(table)
    reads = current_reads_per_cycle(header)
    runs = []
    for chunk in np.split(np.arange(len(t)), np.flatnonzero(np.diff(complete.astype(int))) + 1):
        if complete[chunk[0]] and len(chunk) >= MIN_RUN_SAMPLES:
            runs.append((path, t[chunk], values[chunk], reads))
    return runs


def current_reads_per_cycle(header: dict[str, Any]) -> int:
    """The Present Current reads while a goal was held that a log's current averages: as
    its header's ``current_reads`` says, or its settings (a log that ended without its
    outcome), else 0 (the cycle's own read)."""
    for value in (
        (header.get("current_reads") or {}).get("per_cycle"),
        (header.get("settings") or {}).get("current_reads_per_cycle"),
    ):
        if isinstance(value, int) and value >= 0:
            return value
    return 0


def held_at_the_start(table: pd.DataFrame) -> np.ndarray:
    """Which rows of a log are the executor's hold at the plan's start (n,), bool: the
    load's sag onto the loops as the torque comes on, at rest against friction. Left out of
    identification: on the fourth plant of ``experiments/compensated_cut.py`` they moved the
    identified file's predicted cut of toppra's five-landmark plan, which a breakaway after
    a landmark stop decides, from 0.065 to 0.047 mm (the true cut 0.064)."""
    return table["phase"].astype(str).to_numpy() == "ready"


def check_log_rows(paths: list[Path]) -> None:
    """Refuse logs of more than :data:`~spm_opt.base.input_limits.MAX_LOG_ROWS` rows together,
    before any is parsed: identification holds every row in memory."""
    total = sum(log_rows(Path(path)) for path in paths)
    if total > MAX_LOG_ROWS:
        raise InputError(
            f"logs {named(paths)}: {total:,} rows{' together' if len(paths) > 1 else ''}; "
            f"identification holds every row in memory (about 2.5 kB each) and takes at most "
            f"{MAX_LOG_ROWS:,}: fit fewer or shorter logs (minutes identify a robot)"
        )


def named(paths: list[Path]) -> str:
    """The logs at ``paths`` for a message: the first few."""
    shown = ", ".join(str(path) for path in paths[:3])
    return shown if len(paths) <= 3 else f"{shown} and {len(paths) - 3:,} more"


def log_values(table: pd.DataFrame, columns: tuple[str, ...], path: Path) -> np.ndarray:
    """A log's ``columns`` as floats (rows, columns): an empty cell is NaN (a failed read),
    a cell that holds no number an :class:`InputError` naming its line."""
    cells = table[list(columns)]
    values = cells.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    wrong = np.isnan(values) & cells.notna().to_numpy()
    if np.any(wrong):
        row, column = np.argwhere(wrong)[0]
        raise InputError(
            f"log {path}: line {row + 2}: {columns[column]} = "
            f"{excerpt(str(cells.iloc[row, column]))}: expected a number"
        )
    return values


def _uniform(path: Path, t: np.ndarray, values: np.ndarray, reads: int) -> tuple[float, np.ndarray]:
    """A run's rate (Hz) and its measurements resampled on a uniform grid; the torques,
    with ``reads`` reads between goals, at the middle of the period before each row."""
    step = float(np.median(np.diff(t)))
    if not step > 0.0:
        raise InputError(f"log {path}: time_s does not increase")
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step)) + 1)
    delay = 0.5 * step if reads else 0.0
    measured = [t if k < 4 else t - delay for k in range(values.shape[1])]
    return 1.0 / step, np.stack(
        [np.interp(grid, at, column) for at, column in zip(measured, values.T, strict=True)],
        axis=1,
    )


def correlation_factor(residual: np.ndarray, lags: int) -> float:
    """How much correlated rows inflate the estimates' variance over uncorrelated ones:
    1 + 2 Σ_k (1 − k / (K + 1)) ρ_k over K = ``lags`` (Newey and West's weights), ρ_k the
    autocorrelation of the residuals (M, c), their columns (the joints) pooled, at k rows;
    at least 1 (and 1 for residuals that are all 0)."""
    centred = residual - np.mean(residual, axis=0)
    total = float(np.sum(centred**2))
    if total == 0.0:
        return 1.0
    weighted = sum(
        (1.0 - k / (lags + 1)) * float(np.sum(centred[:-k] * centred[k:])) / total
        for k in range(1, min(lags, len(centred) - 1) + 1)
    )
    return max(1.0, 1.0 + 2.0 * weighted)
