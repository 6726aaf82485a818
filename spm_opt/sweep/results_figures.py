"""A sweep's figures, drawn from the tables :mod:`spm_opt.sweep.results` computes: the key
metrics against a swept parameter, heat maps of a two-parameter grid, and for bone-flap
sweeps the planners' robustness (overall and per swept parameter) and the spread of their
metrics. One colour per planner,
in the order of the ``planners`` given. Each function takes data and returns a figure;
none computes a statistic of its own."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from spm_opt.report.columns import column

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


def against(
    points: pd.DataFrame,
    medians: pd.DataFrame,
    parameter: str,
    planners: Sequence[str],
    name: str,
    bins: int | None = None,
) -> Figure:
    """A panel per metric against ``parameter``, and one of the share of tasks planned and
    clean: each planned task a dot, each planner's medians per value (or quantile bin) a
    line.

    Parameters
    ----------
    points : pandas.DataFrame
        The planned tasks: columns ``planner``, ``parameter`` and the metrics.
    medians : pandas.DataFrame
        Per planner and group, in the groups' order: columns ``planner``, ``at`` (the
        parameter's median in the group), ``planned_rate``, ``clean_rate`` (fractions) and
        each metric's median (the metrics are those of ``points``).
    parameter : str
    planners : sequence of str
        Every planner of the sweep, in the order of their colours.
    name : str
        The sweep's name, for the title.
    bins : int, optional
        The number of quantile bins, when the groups are bins.
    """
    metrics = [m for m in points.columns if m not in ("planner", parameter)]
    figure = _figure((4.2 * min(4, len(metrics) + 1), 3.4 * math.ceil((len(metrics) + 1) / 4)))
    axes = _panels(figure, len(metrics) + 1, 4)
    for index, planner in enumerate(planners):
        mine = medians[medians["planner"] == planner]
        if mine.empty:  # none of its tasks has the parameter
            continue
        colour = _colour(index)
        dots = points[points["planner"] == planner]
        for axis, metric in zip(axes, metrics, strict=False):
            axis.scatter(dots[parameter], dots[metric], s=10, alpha=0.3, color=colour, lw=0)
            axis.plot(mine["at"], mine[metric], "o-", color=colour, markersize=4)
        axes[-1].plot(mine["at"], 100 * mine["clean_rate"], "o-", color=colour, ms=4, label=planner)
        axes[-1].plot(mine["at"], 100 * mine["planned_rate"], "--", color=colour)
    for axis, metric in zip(axes, metrics, strict=False):
        axis.set_title(column(metric).label, fontsize=10)
        values = points[metric].dropna()
        if len(values) and values.min() > 0 and values.max() > 1e3 * values.min():
            axis.set_yscale("log")
    axes[-1].set_title("tasks clean (solid), planned (dashed), %", fontsize=10)
    axes[-1].set_ylim(-5, 105)
    for axis in axes:
        axis.grid(True, alpha=0.3)
    axes[-1].legend(fontsize=8)
    figure.supxlabel(parameter)
    figure.suptitle(
        f"{name}: key metrics against {parameter} (dots: planned tasks; lines: medians"
        + (f" of {bins} quantile bins)" if bins else ")")
    )
    return figure


def heatmap(
    cells: pd.DataFrame,
    parameters: tuple[str, str],
    planner: str,
    metric: str,
    name: str,
    labels: tuple[Sequence[str], Sequence[str]],
) -> Figure:
    """One planner's median ``metric`` over a two-parameter grid (first parameter across,
    second up), each cell annotated; "failed": no task of the cell was planned; "*": one
    breaks a limit.

    Parameters
    ----------
    cells : pandas.DataFrame
        Per cell of every planner: columns ``x``, ``y`` (the indices of the cell's values,
        from 0), ``planner``, ``planned``, ``clean`` (counts) and ``median`` (the metric's,
        over the planned tasks). The colour scale spans every planner's cells.
    parameters : (str, str)
        The parameters across and up.
    planner, metric, name : str
        The planner drawn, the metric, and the sweep's name for the title.
    labels : (sequence of str, sequence of str)
        The parameters' values as text, across and up.
    """
    import matplotlib as mpl

    finite = cells["median"].dropna()
    low, high = (finite.min(), finite.max()) if len(finite) else (0.0, 1.0)
    columns, rows = labels
    grid = np.full((len(rows), len(columns)), np.nan)
    figure = _figure((2.2 + 1.1 * len(columns), 1.6 + 0.8 * len(rows)))
    axis = figure.subplots()
    for cell in cells[cells["planner"] == planner].itertuples(index=False):
        grid[cell.y, cell.x] = cell.median
        if cell.planned == 0:
            text, shade = "failed", 1.0
        else:
            text = f"{cell.median:.3g}" + ("*" if cell.clean < cell.planned else "")
            shade = (cell.median - low) / (high - low) if high > low else 0.5
        colour = "white" if shade < 0.6 else "black"
        axis.text(cell.x, cell.y, text, ha="center", va="center", fontsize=9, color=colour)
    image = axis.imshow(
        np.ma.masked_invalid(grid),
        origin="lower",
        aspect="auto",
        cmap=mpl.colormaps["viridis"].with_extremes(bad="0.85"),
        vmin=low,
        vmax=high,
    )
    figure.colorbar(image, ax=axis, label=column(metric).label)
    axis.set_xticks(range(len(columns)), list(columns))
    axis.set_yticks(range(len(rows)), list(rows))
    axis.set_xlabel(parameters[0])
    axis.set_ylabel(parameters[1])
    axis.set_title(
        f"{name}, {planner}: median {column(metric).label}\n"
        "(*: a task of the cell breaks a limit; failed: none planned)",
        fontsize=10,
    )
    return figure


def flap_robustness(table: pd.DataFrame, flaps: int, name: str) -> Figure:
    """Per planner, the share of the flaps' tasks planned and clean (bars, %, with counts).

    ``table`` has a row per planner, in the order of their colours, indexed by its name:
    columns ``tasks``, ``planned``, ``clean`` (counts) and ``planned_rate``,
    ``clean_rate`` (fractions); ``flaps`` is the number of flaps, for the title.
    """
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
    axis.set_title(f"{name}: robustness over {flaps} generated bone flaps", fontsize=10)
    return figure


def flap_rates(
    rates: Mapping[str, pd.DataFrame], planners: Sequence[str], flaps: int, name: str
) -> Figure:
    """A panel per parameter: each planner's share of tasks clean (solid) and planned
    (dashed), %, per value or bin of the parameter.

    Parameters
    ----------
    rates : mapping of str to pandas.DataFrame
        Per parameter, a row per group and planner, in the groups' order: columns
        ``group`` (the group's label), ``planner``, ``planned_rate`` and ``clean_rate``
        (fractions).
    planners : sequence of str
        Every planner of the sweep, in the order of their colours.
    flaps : int
        The number of flaps, for the title.
    name : str
        The sweep's name, for the title.
    """
    figure = _figure((4.2 * min(4, len(rates)), 3.6 * math.ceil(len(rates) / 4)))
    axes = _panels(figure, len(rates), 4)
    for axis, (parameter, table) in zip(axes, rates.items(), strict=True):
        labels = list(dict.fromkeys(table["group"]))
        at = {label: k for k, label in enumerate(labels)}
        for index, planner in enumerate(planners):
            mine = table[table["planner"] == planner]
            if mine.empty:  # none of its tasks has the parameter
                continue
            x = [at[label] for label in mine["group"]]
            colour = _colour(index)
            axis.plot(x, 100 * mine["clean_rate"], "o-", color=colour, ms=4, label=planner)
            axis.plot(x, 100 * mine["planned_rate"], "--", color=colour)
        axis.set_xticks(range(len(labels)), labels, rotation=30 if len(labels) > 4 else 0)
        axis.set_xlabel(parameter)
        axis.set_ylim(-5, 105)
        axis.grid(True, alpha=0.3)
    axes[0].set_ylabel("tasks clean (solid), planned (dashed), %")
    axes[0].legend(fontsize=8)
    figure.suptitle(f"{name}: robustness over {flaps} generated bone flaps, per parameter")
    return figure


def histograms(points: pd.DataFrame, planners: Sequence[str], name: str) -> Figure:
    """A panel per metric: each planner's histogram over its planned tasks (shared bins).

    ``points`` are the planned tasks: column ``planner`` and one per metric; ``planners``
    every planner of the sweep, in the order of their colours.
    """
    metrics = [m for m in points.columns if m != "planner"]
    figure = _figure((4.2 * min(4, len(metrics)), 3.4 * math.ceil(len(metrics) / 4)))
    axes = _panels(figure, len(metrics), 4)
    for axis, metric in zip(axes, metrics, strict=True):
        values = points[metric].dropna()
        edges = np.histogram_bin_edges(values, bins=min(30, max(5, int(len(values) ** 0.5))))
        for index, planner in enumerate(planners):
            mine = points.loc[points["planner"] == planner, metric].dropna()
            if len(mine):
                colour = _colour(index)
                axis.hist(mine, edges, histtype="step", lw=1.5, color=colour, label=planner)
        axis.set_title(column(metric).label, fontsize=10)
        axis.grid(True, alpha=0.3)
    axes[0].set_ylabel("planned tasks")
    axes[0].legend(fontsize=8)
    figure.suptitle(f"{name}: key metrics over the generated bone flaps, per planner")
    return figure
