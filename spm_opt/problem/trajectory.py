"""The one trajectory type: joint positions of both actuators as a function of time.

Every planner returns a :class:`Trajectory`; the evaluator, the plots and the executor take
nothing else. Inside it is a piecewise polynomial q(t) (2 joints, rad, t in s), evaluated
exactly at any time together with its derivatives. A planner that produces polynomials
hands them over as they are; sampled data (a CSV file) become quintic Hermite pieces that
match position, velocity and acceleration at every sample.

On disk: a CSV with columns ``t,q1,q2,qd1,qd2,qdd1,qdd2`` (SI) and a JSON sidecar of the
same name holding the metadata (planner, the problem it was made for, planner statistics,
package version, breakpoints) and a record of the samples (their count, duration and the
SHA-256 of the CSV's bytes), which reading checks: a CSV cut short, edited or replaced is
refused rather than taken for the plan its sidecar describes.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import BPoly, PPoly

from spm_opt.base.errors import InputError
from spm_opt.base.files import json_default, write_atomically
from spm_opt.base.input_limits import (
    EXCERPT_CHARS,
    MAX_SIDECAR_BYTES,
    MAX_TRAJECTORY_BYTES,
    MAX_TRAJECTORY_ROWS,
    decode_text,
    excerpt,
    read_bytes,
)
from spm_opt.base.version import package_version
from spm_opt.cut.contour import Contour
from spm_opt.model import kinematics

COLUMNS = ("t", "q1", "q2", "qd1", "qd2", "qdd1", "qdd2")
MAX_GRID_SAMPLES = 50_000_000
MAX_DURATION_S = 86_400.0
"""Longest trajectory a CSV file may hold, s (a day)."""
_KIND = "a trajectory CSV"  # what a trajectory file is, for messages
DEFAULT_RATE_HZ = 100.0
_SAME_TIME_S = 1e-9
_SIDE_STEP_S = 1e-9
"""Relative offset, s per s, of the one-sided limits at a breakpoint."""
COLUMN_SUMS_FROM = 256
"""Samples from which :class:`_BernsteinSums` sums each output on its own (it breaks even
at about 200)."""


class Trajectory:
    """Joint positions q(t) of both actuators, shape (2,) per time, rad.

    Parameters
    ----------
    positions : scipy.interpolate.PPoly or BPoly
        Piecewise polynomial of q(t) with 2 outputs, differentiable at least three times
        inside each piece.
    metadata : dict, optional
        Planner name, statistics, ``landmark_times_s`` and anything else a planner records.
    samples : tuple of ndarray, optional
        (t, q, qd, qdd) this trajectory was built from, kept so that writing it back
        reproduces them exactly.
    """

    def __init__(
        self,
        positions: PPoly | BPoly,
        metadata: dict[str, Any] | None = None,
        samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self._q = positions
        self._derivatives = [positions.derivative(n) for n in (1, 2, 3)]
        self.metadata: dict[str, Any] = dict(metadata or {})
        self._samples = samples

    @classmethod
    def from_samples(
        cls,
        t: np.ndarray,
        q: np.ndarray,
        qd: np.ndarray,
        qdd: np.ndarray,
        metadata: dict[str, Any] | None = None,
    ) -> Trajectory:
        """Quintic Hermite pieces through samples: t (N,), s; q, qd, qdd (N, 2), SI.

        Each piece's Bernstein coefficients follow from q, q̇, q̈ at its two ends in closed
        form (what ``BPoly.from_derivatives`` computes, without its Python loop per piece).
        """
        t, q, qd, qdd = (np.asarray(a, dtype=float) for a in (t, q, qd, qdd))
        h = np.diff(t)[:, None]
        coefficients = [
            q[:-1],
            q[:-1] + h * qd[:-1] / 5.0,
            q[:-1] + 2.0 * h * qd[:-1] / 5.0 + h**2 * qdd[:-1] / 20.0,
            q[1:] - 2.0 * h * qd[1:] / 5.0 + h**2 * qdd[1:] / 20.0,
            q[1:] - h * qd[1:] / 5.0,
            q[1:],
        ]
        return cls(BPoly(np.stack(coefficients), t), metadata, samples=(t, q, qd, qdd))

    @property
    def start_time(self) -> float:
        """The first time, s."""
        return float(self._q.x[0])

    @property
    def end_time(self) -> float:
        """The last time, s."""
        return float(self._q.x[-1])

    @property
    def duration(self) -> float:
        """Length of the trajectory, s."""
        return self.end_time - self.start_time

    @property
    def breakpoints(self) -> np.ndarray:
        """Times (M,), s, where the polynomial pieces meet."""
        return np.asarray(self._q.x, dtype=float)

    def local_coefficients(self) -> np.ndarray:
        """Coefficients (degree + 1, pieces, 2) of each piece in the time since it began,
        highest power first (scipy's PPoly layout)."""
        poly = self._q if isinstance(self._q, PPoly) else PPoly.from_bernstein_basis(self._q)
        return np.asarray(poly.c)

    @property
    def landmark_times(self) -> np.ndarray | None:
        """Times, s, at which the planner says each landmark visit happens, if it says."""
        times = self.metadata.get("landmark_times_s")
        return None if times is None else np.asarray(times, dtype=float)

    def _clip(self, t: np.ndarray | float) -> np.ndarray:
        return np.clip(np.asarray(t, dtype=float), self.start_time, self.end_time)

    def position(self, t: np.ndarray | float) -> np.ndarray:
        """q(t), shape (N, 2), rad. Times outside the trajectory take its end values."""
        return _evaluate(self._q, self._clip(t))

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        """q̇(t), shape (N, 2), rad/s."""
        return self._derivative(0, t)

    def acceleration(self, t: np.ndarray | float) -> np.ndarray:
        """q̈(t), shape (N, 2), rad/s²."""
        return self._derivative(1, t)

    def jerk(self, t: np.ndarray | float) -> np.ndarray:
        """Third derivative of q(t), shape (N, 2), rad/s³ (one-sided at breakpoints)."""
        return self._derivative(2, t)

    def states(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """q, q̇, q̈ and the jerk at times t (N,), each (N, 2), SI: what :meth:`position`,
        :meth:`velocity`, :meth:`acceleration` and :meth:`jerk` give, computed together."""
        t = np.asarray(t, dtype=float)
        inside = self._clip(t)
        sums = _BernsteinSums(self._q.x, inside) if _sums_faster(self._q) else None
        position, *derivatives = (
            _evaluate(poly, inside, sums) for poly in (self._q, *self._derivatives)
        )
        outside = (t < self.start_time) | (t > self.end_time)
        if np.any(outside):
            derivatives = [np.where(outside[..., None], 0.0, values) for values in derivatives]
        velocity, acceleration, jerk = derivatives
        return position, velocity, acceleration, jerk

    def acceleration_steps(self) -> tuple[np.ndarray, np.ndarray]:
        """Where q̈ jumps: times (K,), s, and steps (K, 2), rad/s², at the start (from rest),
        at every inner breakpoint (right minus left limit) and at the end (to rest)."""
        inner = self.breakpoints[1:-1]
        side = _SIDE_STEP_S * np.maximum(1.0, np.abs(inner))[:, None]
        left = self._derivatives[1](inner - side[:, 0])
        right = self._derivatives[1](inner + side[:, 0])
        steps = np.vstack(
            [
                self.acceleration([self.start_time]),
                np.reshape(right - left, (-1, 2)),
                -self.acceleration([self.end_time]),
            ]
        )
        return np.concatenate([[self.start_time], inner, [self.end_time]]), steps

    def _derivative(self, index: int, t: np.ndarray | float) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        values = _evaluate(self._derivatives[index], self._clip(t))
        outside = (t < self.start_time) | (t > self.end_time)
        return np.where(outside[..., None], 0.0, values) if np.any(outside) else values

    def time_grid(self, rate_hz: float = DEFAULT_RATE_HZ) -> np.ndarray:
        """Sample times at ``rate_hz`` from the start, with every breakpoint and the end."""
        breaks = self.breakpoints
        if self.duration * rate_hz > MAX_GRID_SAMPLES:
            raise InputError(
                f"trajectory of {self.duration:g} s sampled at {rate_hz:g} Hz: more than "
                f"{MAX_GRID_SAMPLES:,} samples; shorten it or lower the rate"
            )
        uniform = self.start_time + np.arange(0.0, self.duration, 1.0 / rate_hz)
        right = np.clip(np.searchsorted(breaks, uniform), 1, len(breaks) - 1)
        gap = np.minimum(np.abs(uniform - breaks[right - 1]), np.abs(breaks[right] - uniform))
        return _sorted_union(uniform[gap > _SAME_TIME_S], breaks)

    def samples(self, rate_hz: float | None = None) -> tuple[np.ndarray, ...]:
        """(t, q, qd, qdd): the samples it was built from, or a grid at ``rate_hz``."""
        if rate_hz is None and self._samples is not None:
            return self._samples
        t = self.time_grid(rate_hz or DEFAULT_RATE_HZ)
        return t, self.position(t), self.velocity(t), self.acceleration(t)

    def time_scaled(self, rate: float) -> Trajectory:
        """The same path run ``rate`` times as fast: q̃(t) = q(rate · t), rate > 0.

        Each piece keeps its polynomial in the time since it began, its k-th power
        coefficient times rateᵏ (its Bernstein coefficients as they are); the breakpoints
        and the landmark times are divided by ``rate``.
        """
        if not (np.isfinite(rate) and rate > 0.0):
            raise InputError(f"rate = {excerpt(rate)}: expected a positive number")
        breaks = self._q.x / rate
        if isinstance(self._q, BPoly):
            poly: PPoly | BPoly = BPoly(self._q.c, breaks)
        else:
            powers = rate ** np.arange(self._q.c.shape[0] - 1, -1, -1.0)
            poly = PPoly(self._q.c * powers[:, None, None], breaks)
        metadata = dict(self.metadata)
        if self.landmark_times is not None:
            metadata["landmark_times_s"] = (self.landmark_times / rate).tolist()
        return Trajectory(poly, metadata)

    def resample(self, rate_hz: float) -> Trajectory:
        """A sampled copy at ``rate_hz`` (breakpoints kept), as a CSV file would hold it."""
        return Trajectory.from_samples(*self.samples(rate_hz), metadata=self.metadata)

    def platform_points(self, t: np.ndarray, r_u: float) -> np.ndarray:
        """Upper platform mass centre B(t), shape (N, 3), m."""
        return kinematics.forward_kinematics(self.position(t), r_u)

    def cut_points(self, contour: Contour, t: np.ndarray) -> np.ndarray:
        """Where the tool meets the skull at times t: (N, 3), m."""
        return contour.cut_points(kinematics.forward_kinematics(self.position(t), 1.0))

    def tool_speed(self, contour: Contour, t: np.ndarray) -> np.ndarray:
        """Speed of the cut point across the skull at times t: (N,), m/s."""
        return contour.joint_tool_speed(self.position(t), self.velocity(t))

    # --- files --------------------------------------------------------------------

    def to_csv(self, path: str | Path, rate_hz: float | None = None) -> None:
        """Write FILE.csv and its FILE.json sidecar, both or neither (see :meth:`csv_files`)."""
        write_atomically(self.csv_files(Path(path), rate_hz))

    def csv_files(self, path: Path, rate_hz: float | None = None) -> dict[Path, str]:
        """The text of FILE.json, the sidecar, and FILE.csv, in that order, by path,
        without writing them.

        The samples are the ones it was built from, or a grid at ``rate_hz`` (default
        100 Hz) that includes every breakpoint, so reading the file back gives the same
        polynomial pieces for a trajectory of cubic or quintic pieces; at most
        :data:`~spm_opt.base.input_limits.MAX_TRAJECTORY_ROWS` of them. The sidecar records the
        SHA-256 of the CSV's bytes and comes first: :func:`~spm_opt.base.files.write_atomically`
        renames in order, so a write killed between its renames leaves the new sidecar
        beside the old CSV (or none), which :meth:`from_csv` refuses, never a new CSV beside
        an old sidecar (which might record no hash) or none.
        """
        self._check_csv_rows(rate_hz)
        t, q, qd, qdd = self.samples(rate_hz)
        table = np.column_stack([t, q[:, 0], q[:, 1], qd[:, 0], qd[:, 1], qdd[:, 0], qdd[:, 1]])
        lines = [",".join(COLUMNS)] + [",".join(repr(v) for v in row) for row in table.tolist()]
        text = "\n".join(lines) + "\n"
        sidecar = {
            **self.metadata,
            "columns": {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2"},
            "breakpoints_s": self.breakpoints.tolist(),
            "spm_opt_version": self.metadata.get("spm_opt_version", package_version()),
            "samples": _samples_record(text.encode("utf-8"), t),
        }
        return {
            sidecar_path(path): json.dumps(sidecar, indent=2, default=json_default) + "\n",
            path: text,
        }

    def _check_csv_rows(self, rate_hz: float | None) -> None:
        """Refuse to write a CSV of more samples than :meth:`from_csv` reads, before
        sampling (breakpoints on the grid count twice: an upper bound)."""
        if rate_hz is None and self._samples is not None:
            rows, sampled = len(self._samples[0]), "as built"
        else:
            rate = rate_hz or DEFAULT_RATE_HZ
            rows = math.floor(self.duration * rate) + 1 + len(self.breakpoints)
            sampled = f"at {rate:g} Hz"
        if rows > MAX_TRAJECTORY_ROWS:
            raise InputError(
                f"trajectory of {self.duration:g} s sampled {sampled}: {rows:,} samples; a "
                f"trajectory CSV holds at most {MAX_TRAJECTORY_ROWS:,}: lower the rate"
            )

    @classmethod
    def from_csv(cls, path: str | Path) -> Trajectory:
        """Read a trajectory CSV (and its JSON sidecar, when there is one).

        Raises :class:`InputError` when the sidecar records samples (every file
        :meth:`to_csv` writes does) whose bytes are not the CSV's: the pair is
        inconsistent (a write killed between its renames, or the CSV cut short, edited or
        replaced).
        A sidecar without that record (written by hand, or by an older spm_opt) is read as
        it is. The CSV may hold at most :data:`~spm_opt.base.input_limits.MAX_TRAJECTORY_ROWS`
        samples in :data:`~spm_opt.base.input_limits.MAX_TRAJECTORY_BYTES`.
        """
        path = Path(path)
        data = read_bytes(path, _KIND, MAX_TRAJECTORY_BYTES)
        metadata = _read_sidecar(sidecar_path(path))
        if metadata:
            _check_landmark_times(sidecar_path(path), metadata.get("landmark_times_s"))
            _check_samples_record(path, metadata.get("samples"), data)
        t, q, qd, qdd = _read_samples(path, data)
        return cls.from_samples(t, q, qd, qdd, metadata)


def _sorted_union(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """``np.union1d`` of two ascending arrays, merged without sorting them again."""
    merged = np.insert(first, np.searchsorted(first, second), second)
    return merged[np.concatenate([[True], merged[1:] != merged[:-1]])]


def _evaluate(poly: PPoly | BPoly, t: np.ndarray, sums: _BernsteinSums | None = None) -> np.ndarray:
    """``poly(t)``, shape t.shape + (outputs,). Bernstein pieces beyond the degrees scipy
    sums in closed form go through :class:`_BernsteinSums` (``sums``, when given at the
    same times and breakpoints): the same values, faster."""
    if not _sums_faster(poly):
        return np.asarray(poly(t))
    return (sums or _BernsteinSums(poly.x, t))(poly.c)


def _sums_faster(poly: PPoly | BPoly) -> bool:
    """Whether :class:`_BernsteinSums` evaluates ``poly`` (Bernstein pieces of degree 4 or
    more along axis 0; scipy's closed forms for lower degrees are faster)."""
    return isinstance(poly, BPoly) and poly.axis == 0 and poly.c.ndim == 3 and len(poly.c) > 4


class _BernsteinSums:
    """Σ_j C(k, j) s^j (1 − s)^(k−j) c_j at times t, for Bernstein coefficients c of
    degree k between ``breakpoints``, s the time within the piece over its length; times
    beyond the breakpoints use the end pieces.

    The arithmetic of scipy's ``BPoly`` in the same order, with libm's ``pow`` for the
    powers (``np.float_power``), so the results are scipy's to the bit; vectorised over t,
    with where the times fall and each power of s and 1 − s computed once for every output
    and every polynomial on the same breakpoints.
    """

    def __init__(self, breakpoints: np.ndarray, t: np.ndarray) -> None:
        t = np.asarray(t, dtype=float)
        times = t.ravel()
        last = len(breakpoints) - 2
        self.shape = t.shape
        self.piece = np.clip(np.searchsorted(breakpoints, times, side="right") - 1, 0, last)
        start = breakpoints[self.piece]
        s = (times - start) / (breakpoints[self.piece + 1] - start)
        self._rising = [np.ones_like(s), s]
        self._falling = [np.ones_like(s), 1.0 - s]

    def __call__(self, coefficients: np.ndarray) -> np.ndarray:
        """Values, shape t.shape + (outputs,), of coefficients (k + 1, pieces, outputs).

        The pieces' coefficients are gathered by ``np.take`` (many times quicker than
        indexing). From :data:`COLUMN_SUMS_FROM` samples on, each output is summed in a
        contiguous array of its own, several times quicker than all in one (N, outputs)
        array, which costs fewer calls on a few samples (a control cycle's one).
        """
        degree, outputs = len(coefficients) - 1, coefficients.shape[2]
        by_column = len(self.piece) >= COLUMN_SUMS_FROM
        total = np.zeros((outputs, len(self.piece)) if by_column else (len(self.piece), outputs))
        comb = 1.0
        for j in range(degree + 1):
            weight = comb * _power(self._rising, j) * _power(self._falling, degree - j)
            gathered = np.take(coefficients[j], self.piece, axis=0)  # (samples, outputs)
            if by_column:
                for row, column in zip(total, gathered.T, strict=True):
                    row += weight * column
            else:
                total += weight[:, None] * gathered
            comb *= 1.0 * (degree - j) / (j + 1.0)
        values = np.ascontiguousarray(total.T) if by_column else total
        return values.reshape(self.shape + coefficients.shape[2:])


def _power(powers: list[np.ndarray], exponent: int) -> np.ndarray:
    """x**exponent from ``powers`` = [x**0, x**1, ...], extended as needed with libm's pow
    (x**0 = 1 and x**1 = x exactly, as pow gives them)."""
    while len(powers) <= exponent:
        powers.append(np.float_power(powers[1], float(len(powers))))
    return powers[exponent]


def sidecar_path(path: Path) -> Path:
    """The JSON metadata file beside a trajectory CSV."""
    return path.with_suffix(".json")


def _check_landmark_times(sidecar: Path, times: Any) -> None:
    if times is None:
        return
    valid = isinstance(times, list) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) for v in times
    )
    if not valid:
        raise InputError(
            f"{sidecar}: landmark_times_s = {excerpt(times)}: expected a list of times in s"
        )


def _samples_record(data: bytes, t: np.ndarray) -> dict[str, Any]:
    """What a sidecar records of its CSV: the sample count, the duration (s) and the
    SHA-256 of the CSV's bytes."""
    return {
        "count": len(t),
        "duration_s": float(t[-1] - t[0]),
        "sha256": hashlib.sha256(data).hexdigest(),
    }


def _check_samples_record(path: Path, recorded: Any, data: bytes) -> None:
    """Refuse a CSV whose bytes are not those its sidecar records (no record: nothing to
    check, as for a sidecar written by hand or by an older spm_opt)."""
    if recorded is None:
        return
    sidecar = sidecar_path(path).name
    expected = ("count", "duration_s", "sha256")
    if (
        not isinstance(recorded, dict)
        or sorted(recorded) != sorted(expected)
        or not isinstance(recorded["sha256"], str)
        or not all(isinstance(recorded[k], int | float) for k in ("count", "duration_s"))
    ):
        raise InputError(
            f"{path.parent / sidecar}: samples = {excerpt(recorded)}: expected "
            f"{{{', '.join(expected)}}} as spm-opt writes them"
        )
    if hashlib.sha256(data).hexdigest() != recorded["sha256"]:
        raise InputError(
            f"{path}: not the CSV its sidecar {sidecar} records ({recorded['count']:,} samples "
            f"over {recorded['duration_s']:g} s, SHA-256 {recorded['sha256'][:12]}…): the pair "
            "is inconsistent (a write killed between its files, or the CSV cut short, edited "
            "or replaced); plan it again"
        )


def _read_sidecar(sidecar: Path) -> dict[str, Any]:
    """The metadata a trajectory's JSON sidecar holds; none when there is no sidecar (a
    directory or a pipe of its name is an error)."""
    if not sidecar.exists():
        return {}
    kind = "a trajectory's JSON sidecar"
    text = decode_text(read_bytes(sidecar, kind, MAX_SIDECAR_BYTES), sidecar, kind)
    try:
        metadata = json.loads(text)
    except json.JSONDecodeError as error:
        raise InputError(f"{sidecar}: not valid JSON: {error}") from None
    except (ValueError, RecursionError) as error:  # a huge integer, deep nesting
        raise InputError(f"{sidecar}: not valid JSON: {str(error).split(':')[0]}") from None
    if not isinstance(metadata, dict):
        raise InputError(f"{sidecar}: expected a JSON object")
    return metadata


def _read_samples(path: Path, data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The samples (t, q, qd, qdd) of a trajectory CSV's bytes, checked."""
    if data.count(b"\n") - 1 > MAX_TRAJECTORY_ROWS:
        raise _too_many_samples(path)
    rows = csv.reader(io.StringIO(decode_text(data, path, _KIND), newline=""))
    lines = data.count(b"\n") + data.count(b"\r") + 1  # at least the rows
    try:
        values = _parse_rows(path, rows, min(lines, MAX_TRAJECTORY_ROWS + 1))
    except csv.Error as error:
        raise InputError(
            f"{path}: line {rows.line_num}: not CSV ({error}); expected {_KIND}"
        ) from None
    if len(values) < 2:
        raise InputError(f"{path}: {len(values)} samples; expected at least 2")
    span = values[-1, 0] - values[0, 0]
    if span > MAX_DURATION_S:
        raise InputError(
            f"{path}: column t spans {span:g} s; expected at most {MAX_DURATION_S:g} s"
        )
    steps = np.diff(values[:, 0])
    if np.any(steps <= 0.0):
        line = int(np.argmax(steps <= 0.0)) + 3
        raise InputError(f"{path}: line {line}, column t: times must increase strictly")
    return values[:, 0], values[:, 1:3], values[:, 3:5], values[:, 5:7]


def _parse_rows(path: Path, rows: Iterator[list[str]], lines: int) -> np.ndarray:
    """The values (samples, 7) of the CSV's ``rows``, at most ``lines`` with the header
    (the header first, then finite numbers, 7 a row)."""
    header = next(rows, None)
    if header is None or tuple(c.strip() for c in header) != COLUMNS:
        found = "empty file"
        if header is not None:
            found = f"header is {excerpt(','.join(c[:EXCERPT_CHARS] for c in header[:8]))}"
        raise InputError(f"{path}: {found}; expected the header {','.join(COLUMNS)}")
    values = np.empty((lines - 1, len(COLUMNS)))
    count = 0
    for number, row in enumerate(rows, start=2):
        if count == len(values):
            raise _too_many_samples(path)
        if len(row) != len(COLUMNS):
            raise InputError(
                f"{path}: line {number} has {len(row)} values; expected {len(COLUMNS)}"
            )
        numbers = [_finite(text) for text in row]
        if None in numbers:
            column = numbers.index(None)
            where = f"{path}: line {number}, column {COLUMNS[column]} = {excerpt(row[column])}"
            raise InputError(f"{where}: expected a finite number")
        values[count] = numbers
        count += 1
    return values[:count]


def _too_many_samples(path: Path) -> InputError:
    return InputError(
        f"{path}: more than {MAX_TRAJECTORY_ROWS:,} samples; expected {_KIND} of at most "
        f"{MAX_TRAJECTORY_ROWS:,} samples"
    )


def _finite(text: str) -> float | None:
    """The finite number ``text`` holds, else None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
