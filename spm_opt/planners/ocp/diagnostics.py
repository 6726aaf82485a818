"""What a solve's constraint rows say in words: the most violated row (or the nearest to
binding), its value and limit, and where on the grid it stands."""

from __future__ import annotations

import math

import numpy as np

from spm_opt.planners.ocp.nlp import Nlp
from spm_opt.planners.ocp.point import GAUSS, GAUSS_FRACTIONS, INSIDE, NODE
from spm_opt.planners.ocp.transcription import STATE, RowGroup


def _place_offset(group: RowGroup, fractions: np.ndarray, interval: int) -> float:
    """Where in its interval a group's point sits, as a fraction of the interval."""
    if group.place == INSIDE:
        return float(fractions[group.point, interval])
    if group.place == GAUSS:
        return GAUSS_FRACTIONS[group.point]
    return 0.0 if group.place == NODE else 0.5


def excess(values: np.ndarray, low: np.ndarray, high: np.ndarray, squared: bool) -> np.ndarray:
    """Excess of rows over their bounds, relative to the bound (−inf where unbounded);
    rows that hold squares are compared by their square roots."""
    if squared:
        values, low = np.sqrt(np.maximum(values, 0.0)), np.full_like(low, -np.inf)
        high = np.sqrt(high)
    limit = np.where(np.isfinite(high), high, low)
    relevant = np.isfinite(limit)
    beyond = np.where(relevant, np.maximum(values - high, low - values), -np.inf)
    relative = np.full(values.shape, -np.inf)
    np.divide(beyond, np.maximum(np.abs(limit), 1e-12), out=relative, where=relevant)
    return relative


def interval_rows(nlp: Nlp, vector: np.ndarray) -> np.ndarray:
    """The interval rows of g (or of its bounds) as (M, rows per interval)."""
    m = nlp.grid.intervals
    return np.reshape(vector[: m * nlp.rows_per_interval], (m, nlp.rows_per_interval))


def worst_constraint(
    nlp: Nlp,
    g: np.ndarray,
    box: dict[str, np.ndarray],
    fractions: np.ndarray,
    names: list[str],
) -> str:
    """The most violated constraint (or, with none violated, the nearest to binding), in
    words: what, its value and limit, and where."""
    values, low, high = (interval_rows(nlp, v) for v in (g, box["lbg"], box["ubg"]))
    best: tuple[float, str] | None = None
    grid = nlp.grid
    for group in nlp.groups:
        columns = slice(STATE + group.start, STATE + group.start + group.size)
        squared = group.constraint.squared
        relative = excess(values[:, columns], low[:, columns], high[:, columns], squared)
        interval, row = np.unravel_index(int(np.argmax(relative)), relative.shape)
        if not np.isfinite(relative[interval, row]):
            continue
        if best is not None and relative[interval, row] <= best[0]:
            continue
        value, bound = values[interval, columns][row], high[interval, columns][row]
        if not np.isfinite(bound):
            bound = low[interval, columns][row]
        if squared:
            value, bound = math.sqrt(max(value, 0.0)), math.sqrt(bound)
        segment = int(grid.interval_segments[interval])
        position = interval - segment * grid.per_segment + _place_offset(group, fractions, interval)
        unit = group.constraint.unit
        best = (
            relative[interval, row],
            f"{group.constraint.name} {value:.4g} {unit} against {bound:.4g} {unit} in "
            f"segment {names[segment]}→{names[segment + 1]}, "
            f"at {position:.3g} of its {grid.per_segment} intervals",
        )
    return "none" if best is None else best[1]
