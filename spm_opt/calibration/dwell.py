"""Pairing a tracker's recording with the calibration run's dwells, without a shared clock.

The run's log says when, on the robot's clock, the robot dwelt at each pose, and what its
encoders read throughout. The tracker's own clock is offset from the robot's by an unknown
constant. Both show when the marker is still: a sample is still when the median of the
marker's positions over :data:`HALF_WINDOW_S` before it and the median over as long after
it lie within a threshold of each other. The threshold is :data:`STILL_M`, or more for a
noisy or slow tracker: :data:`GAP_SIGMAS` standard deviations of the gap between two
medians of still samples, from the tracker's jitter as its second differences measure it
(:func:`jitter_m`). Medians over 0.4 s average a jitter of 0.1–0.25 mm down to a few
hundredths at 60 Hz, while a move of this robot covers millimetres in that time; the log's
path is judged with the same threshold. The log's marker is where the ideal kinematics put
it at the logged readings (the error angles move it by far less than a move does). The
offset is the one at which the tracker's still samples agree most with the log's (a search
at :data:`COARSE_STEP_S`, then :data:`LAG_STEP_S`); the moves between poses differ in
length, so the pattern agrees at one offset only. Each pose's position is then the mean of
the tracker's samples inside its averaging window, moved by the offset and trimmed at both
ends by :data:`TRIM_S`. Frames the tracker lost are absent from the recording: a window
of time, not of samples, spans them, so a dropout does not split a dwell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.verify.motion_capture import MarkerTrack

HALF_WINDOW_S = 0.4
"""Each half of the window whose medians decide whether a sample is still, s."""

STILL_M = 0.2e-3
"""Least threshold on the distance between the two medians of a still sample, m."""

GAP_SIGMAS = 4.0
"""The threshold in standard deviations of a still sample's gap between medians: the gap's
length is then above it for about 0.1 % of still samples (a χ distribution of 3 degrees of
freedom)."""

COARSE_STEP_S = 0.1
LAG_STEP_S = 0.02
"""Steps of the search for the tracker clock's offset, s: over every offset at the coarse
step, then about the best at the fine one (agreement falls off over a whole move, so the
coarse step cannot step over its peak)."""

MIN_AGREEMENT = 0.9
"""Share of the log's samples whose stillness the tracker must agree with at the offset."""

TRIM_S = 0.1
"""Time left out at each end of an averaging window, s: the offset is known to a step."""

MIN_SAMPLES = 10
"""Fewest tracker samples a pose's mean takes."""


@dataclass(frozen=True)
class DwellMeans:
    """Per pose: the marker's mean position (n, 3), m, and its sample count (n,); the
    tracker clock's offset (tracker time − log time), s, and the share of the log's samples
    whose stillness the tracker agreed with at it."""

    means_m: np.ndarray
    counts: np.ndarray
    lag_s: float
    agreement: float


def jitter_m(times_s: np.ndarray, points_m: np.ndarray) -> float:
    """A tracker's jitter, the standard deviation per coordinate of its samples about the
    marker's path, m, from its path (times (k,), s; points (k, 3), m).

    The median of the second differences' absolute values over runs of three samples evenly
    spaced in time, over 0.6745 √6: robust to the moves, whose second differences at a
    tracker's rate are far below its jitter, and to the dropouts, which leave a run uneven.
    """
    steps = np.diff(times_s)
    if len(steps) < 2:
        return 0.0
    even = np.abs(steps[1:] - steps[:-1]) <= 0.25 * np.minimum(steps[1:], steps[:-1])
    second = points_m[2:][even] - 2.0 * points_m[1:-1][even] + points_m[:-2][even]
    if not second.size:
        return 0.0
    return float(np.median(np.abs(second))) / (0.6745 * np.sqrt(6.0))


def still_threshold(times_s: np.ndarray, points_m: np.ndarray) -> float:
    """The threshold on a sample's gap between medians for a tracker's path (times (k,), s;
    points (k, 3), m): :data:`STILL_M`, or :data:`GAP_SIGMAS` standard deviations of the gap
    (a median of n samples has 1.2533 σ/√n), m."""
    span = float(times_s[-1] - times_s[0]) if len(times_s) > 1 else 0.0
    per_half = max(len(times_s) * HALF_WINDOW_S / span, 1.0) if span > 0.0 else 1.0
    gap = 1.2533 * jitter_m(times_s, points_m) * np.sqrt(2.0 / per_half)
    return max(STILL_M, GAP_SIGMAS * gap)


def still_samples(
    times_s: np.ndarray, points_m: np.ndarray, threshold_m: float = STILL_M
) -> np.ndarray:
    """Whether each sample (k,) of a marker's path (times (k,), s; points (k, 3), m) is
    still: its gap between medians at most ``threshold_m``, m (see the module's docstring)."""
    still = np.zeros(len(times_s), dtype=bool)
    starts = np.searchsorted(times_s, times_s - HALF_WINDOW_S)
    ends = np.searchsorted(times_s, times_s + HALF_WINDOW_S, side="right")
    for k in range(len(times_s)):
        before, after = points_m[starts[k] : k + 1], points_m[k : ends[k]]
        if len(before) >= 3 and len(after) >= 3:
            gap = np.median(before, axis=0) - np.median(after, axis=0)
            still[k] = float(np.linalg.norm(gap)) <= threshold_m
    return still


def _nearest(times: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The index of ``times``' sample nearest each of ``at``, and whether it lies within
    two of the recording's periods (else the recording has no sample there)."""
    index = np.clip(np.searchsorted(times, at), 1, len(times) - 1)
    left_closer = (at - times[index - 1]) < (times[index] - at)
    index = np.where(left_closer, index - 1, index)
    period = (times[-1] - times[0]) / max(len(times) - 1, 1)
    return index, np.abs(times[index] - at) <= 2.0 * period + LAG_STEP_S


def dwell_means(
    track: MarkerTrack,
    log_times_s: np.ndarray,
    log_marker_m: np.ndarray,
    windows_s: np.ndarray,
    source: str,
) -> DwellMeans:
    """The marker's mean position in each averaging window ``windows_s`` (n, 2), s on the
    log's clock (start, end), from a tracker's ``track`` named ``source``, aligned with the
    log's marker path (times (k,), s; positions (k, 3), m, in any frame).

    Raises
    ------
    InputError
        If the recording's stillness does not agree with the log's at any offset, or a pose
        has fewer than :data:`MIN_SAMPLES` tracker samples (a marker hidden there).
    """
    windows_s = np.asarray(windows_s, dtype=float)
    times, points = track.times_s, track.points_m
    if len(times) < 2 or len(log_times_s) < 2:
        raise InputError(f"{source}: too short a recording to pair with the run")
    threshold = still_threshold(times, points)
    tracker_still = still_samples(times, points, threshold)
    log_still = still_samples(log_times_s, log_marker_m, threshold)

    def agreement_at(lags: np.ndarray) -> np.ndarray:
        scores = np.empty(len(lags))
        for i, lag in enumerate(lags):
            index, seen = _nearest(times, log_times_s + lag)
            scores[i] = np.mean(seen & (tracker_still[index] == log_still))
        return scores

    coarse = np.arange(
        times[0] - log_times_s[-1], times[-1] - log_times_s[0] + COARSE_STEP_S, COARSE_STEP_S
    )
    centre = coarse[int(np.argmax(agreement_at(coarse)))]
    fine = centre + np.arange(-COARSE_STEP_S, COARSE_STEP_S + LAG_STEP_S / 2, LAG_STEP_S)
    scores = agreement_at(fine)
    best = int(np.argmax(scores))
    lag, agreement = float(fine[best]), float(scores[best])
    if agreement < MIN_AGREEMENT:
        raise InputError(
            f"{source}: the tracker's still and moving stretches do not line up with the "
            f"run's (at best {agreement:.0%} of its samples agree, at least "
            f"{MIN_AGREEMENT:.0%} needed): is it the recording of this run?"
        )
    means, counts = [], []
    for pose, (start, end) in enumerate(windows_s, start=1):
        inside = (times >= start + lag + TRIM_S) & (times <= end + lag - TRIM_S)
        count = int(np.count_nonzero(inside))
        if count < MIN_SAMPLES:
            raise InputError(
                f"{source}: pose {pose}: {count} tracker samples in its dwell, at least "
                f"{MIN_SAMPLES} needed (was the marker hidden there?)"
            )
        means.append(points[inside].mean(axis=0))
        counts.append(count)
    return DwellMeans(np.asarray(means), np.asarray(counts), lag, agreement)
