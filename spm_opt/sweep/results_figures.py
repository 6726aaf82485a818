"""A sweep's figures: the key metrics against each swept parameter, heat maps of a
two-parameter grid, and for bone-flap sweeps the planners' robustness and the spread of
their metrics. One colour per planner, in the order the planners first appear."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from spm_opt.sweep.results import (
    FLAP,
    MAX_LEVELS,
    METRICS,
    groups,
    level_label,
    planner_order,
    robustness,
    shown_metrics,
    swept_parameters,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

_COLOURS = [f"C{k}" for k in range(10)]


def _figure(size: tuple[float, float]) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=size, layout="constrained")


def _colour(index: int) -> str:
    return _COLOURS[index % len(_COLOURS)]


def _panels(figure: Figure, count: int, columns: int) -> list[Axes]:
    """``count`` axes in rows of ``columns``; the grid's unused cells removed."""
    columns = min(columns, count)
    axes = list(figure.subplots(math.ceil(count / columns), columns, squeeze=False).ravel())
    for axis in axes[count:]:
        axis.remove()
    return axes[:count]


def safe_name(text: str) -> str:
    """``robot.friction.mu`` → ``robot_friction_mu``: letters, digits, "-" and "_" only."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_") or "_"


def sweep_figures(
    data: pd.DataFrame, parameters: Sequence[str], name: str
) -> Iterator[tuple[str, Figure]]:
    """Every figure of a sweep, as (file name, figure).

    Parameters
    ----------
    data : pandas.DataFrame
        The sweep's table with its key metrics (:func:`spm_opt.sweep.results.with_metrics`).
    parameters : sequence of str
        Its parameter columns.
    name : str
        The sweep's name, for the titles.

    Yields
    ------
    (str, Figure)
        ``metrics_vs_<parameter>.png`` for each swept numeric parameter (:func:`against`);
        ``heatmap_<planner>_<metric>.png`` for each planner and key metric when exactly two
        parameters are swept, each over at most :data:`MAX_LEVELS` values (:func:`heatmap`);
        ``flap_robustness.png`` and ``flap_histograms.png`` when the sweep has generated
        flaps (:func:`flap_robustness`, :func:`histograms`). Names are filesystem-safe.
    """
    metrics = shown_metrics(data)
    swept = swept_parameters(data, parameters)
    for parameter in swept:
        yield f"metrics_vs_{safe_name(parameter)}.png", against(data, parameter, metrics, name)
    if len(swept) == 2 and all(data[p].nunique() <= MAX_LEVELS for p in swept):
        for planner in planner_order(data).cat.categories:
            for metric in metrics:
                yield (
                    f"heatmap_{safe_name(planner)}_{metric}.png",
                    heatmap(data, (swept[0], swept[1]), planner, metric, name),
                )
    if FLAP in parameters:
        yield "flap_robustness.png", flap_robustness(data, name)
        if metrics:
            yield "flap_histograms.png", histograms(data, metrics, name)


def against(data: pd.DataFrame, parameter: str, metrics: Sequence[str], name: str) -> Figure:
    """A panel per metric against ``parameter``, and one of the share of tasks planned and
    clean: each planned task a dot, each planner's medians per value (or per quantile bin)
    a line, over every other parameter."""
    level = groups(data[parameter])
    planner = planner_order(data)
    table = robustness(data, [level, planner], metrics)
    centre = data[parameter].groupby([level, planner], observed=True).median()
    planned = data["status"] != "failed"
    figure = _figure((4.2 * min(4, len(metrics) + 1), 3.4 * math.ceil((len(metrics) + 1) / 4)))
    axes = _panels(figure, len(metrics) + 1, 4)
    present = set(table.index.get_level_values(1))
    for index, planner_name in enumerate(planner.cat.categories):
        if planner_name not in present:  # none of its tasks has the parameter
            continue
        colour = _colour(index)
        rows = data[planned & (planner == planner_name)]
        stats, x = table.xs(planner_name, level=1), centre.xs(planner_name, level=1)
        for axis, metric in zip(axes, metrics, strict=False):
            axis.scatter(rows[parameter], rows[metric], s=10, alpha=0.3, color=colour, lw=0)
            axis.plot(x, stats[metric], "o-", color=colour, markersize=4)
        axes[-1].plot(x, 100 * stats["clean_rate"], "o-", color=colour, ms=4, label=planner_name)
        axes[-1].plot(x, 100 * stats["planned_rate"], "--", color=colour)
    for axis, metric in zip(axes, metrics, strict=False):
        axis.set_title(METRICS[metric][1], fontsize=10)
        values = data.loc[planned, metric].dropna()
        if len(values) and values.min() > 0 and values.max() > 1e3 * values.min():
            axis.set_yscale("log")
    axes[-1].set_title("tasks clean (solid), planned (dashed), %", fontsize=10)
    axes[-1].set_ylim(-5, 105)
    for axis in axes:
        axis.grid(True, alpha=0.3)
    axes[-1].legend(fontsize=8)
    figure.supxlabel(parameter)
    binned = isinstance(level.dtype, pd.CategoricalDtype)
    figure.suptitle(
        f"{name}: key metrics against {parameter} (dots: planned tasks; lines: medians"
        + (f" of {level.nunique()} quantile bins)" if binned else ")")
    )
    return figure


def heatmap(
    data: pd.DataFrame, parameters: tuple[str, str], planner: str, metric: str, name: str
) -> Figure:
    """One planner's median ``metric`` over a two-parameter grid (first parameter across,
    second up), each cell annotated; the colour scale is shared by every planner's map of
    the metric. "failed": no task of the cell was planned; "*": one breaks a limit."""
    import matplotlib as mpl

    x, y = parameters
    table = robustness(data, [data[x], data[y], planner_order(data)], [metric])
    finite = table[metric].dropna()
    low, high = (finite.min(), finite.max()) if len(finite) else (0.0, 1.0)
    columns, rows = sorted(data[x].dropna().unique()), sorted(data[y].dropna().unique())
    grid = np.full((len(rows), len(columns)), np.nan)
    figure = _figure((2.2 + 1.1 * len(columns), 1.6 + 0.8 * len(rows)))
    axis = figure.subplots()
    for (x_value, y_value, planner_name), cell in table.iterrows():
        if planner_name != planner:
            continue
        i, j = rows.index(y_value), columns.index(x_value)
        grid[i, j] = cell[metric]
        if cell["planned"] == 0:
            text, shade = "failed", 1.0
        else:
            text = f"{cell[metric]:.3g}" + ("*" if cell["clean"] < cell["planned"] else "")
            shade = (cell[metric] - low) / (high - low) if high > low else 0.5
        colour = "white" if shade < 0.6 else "black"
        axis.text(j, i, text, ha="center", va="center", fontsize=9, color=colour)
    image = axis.imshow(
        np.ma.masked_invalid(grid),
        origin="lower",
        aspect="auto",
        cmap=mpl.colormaps["viridis"].with_extremes(bad="0.85"),
        vmin=low,
        vmax=high,
    )
    figure.colorbar(image, ax=axis, label=METRICS[metric][1])
    axis.set_xticks(range(len(columns)), [level_label(v) for v in columns])
    axis.set_yticks(range(len(rows)), [level_label(v) for v in rows])
    axis.set_xlabel(x)
    axis.set_ylabel(y)
    axis.set_title(
        f"{name}, {planner}: median {METRICS[metric][1]}\n"
        "(*: a task of the cell breaks a limit; failed: none planned)",
        fontsize=10,
    )
    return figure


def flap_robustness(data: pd.DataFrame, name: str) -> Figure:
    """Per planner, the share of the flaps' tasks planned and clean (bars, %, with counts)."""
    planner = planner_order(data)
    table = robustness(data, [planner], [])
    figure = _figure((1.5 + 1.2 * len(table), 4.5))
    axis = figure.subplots()
    at = np.arange(len(table))
    colours = [_colour(k) for k in range(len(table))]
    for offset, share, count, style in (
        (-0.2, "planned_rate", "planned", {"alpha": 0.45, "label": "planned"}),
        (0.2, "clean_rate", "clean", {"label": "clean (no limit broken)"}),
    ):
        bars = axis.bar(at + offset, 100 * table[share], width=0.4, color=colours, **style)
        counts = [f"{k}/{n}" for k, n in zip(table[count], table["tasks"], strict=True)]
        axis.bar_label(bars, counts, fontsize=8)
    axis.set_xticks(at, list(table.index))
    axis.set_ylim(0, 110)
    axis.set_ylabel("tasks (%)")
    axis.grid(True, axis="y", alpha=0.3)
    axis.legend(fontsize=8, loc="lower right")
    flaps = data[FLAP].nunique()
    axis.set_title(f"{name}: robustness over {flaps} generated bone flaps", fontsize=10)
    return figure


def histograms(data: pd.DataFrame, metrics: Sequence[str], name: str) -> Figure:
    """A panel per metric: each planner's histogram over its planned tasks (shared bins)."""
    planner = planner_order(data)
    planned = data["status"] != "failed"
    figure = _figure((4.2 * min(4, len(metrics)), 3.4 * math.ceil(len(metrics) / 4)))
    axes = _panels(figure, len(metrics), 4)
    for axis, metric in zip(axes, metrics, strict=True):
        values = data.loc[planned, metric].dropna()
        edges = np.histogram_bin_edges(values, bins=min(30, max(5, int(len(values) ** 0.5))))
        for index, planner_name in enumerate(planner.cat.categories):
            mine = data.loc[planned & (planner == planner_name), metric].dropna()
            if len(mine):
                colour = _colour(index)
                axis.hist(mine, edges, histtype="step", lw=1.5, color=colour, label=planner_name)
        axis.set_title(METRICS[metric][1], fontsize=10)
        axis.grid(True, alpha=0.3)
    axes[0].set_ylabel("planned tasks")
    axes[0].legend(fontsize=8)
    figure.suptitle(f"{name}: key metrics over the generated bone flaps, per planner")
    return figure
