"""A sweep's figures, drawn from the tables :mod:`spm_opt.studies.sweep.results` computes: the key
metrics against a swept parameter, heat maps of a two-parameter grid, and for bone-flap
sweeps the planners' robustness (overall and per swept parameter) and the spread of their
metrics. One colour and line style per planner, in the order of the ``planners`` given.
Each function takes data and returns a figure; none computes a statistic of its own.

Axes carry their units: a metric's from :mod:`spm_opt.report.columns` ("(-)" for a
ratio), a parameter's from the suffix of its key (``_mm_s`` → mm/s; "(count)" for the
flaps' landmarks, "(-)" for a key without one, such as ``robot.friction.mu``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from spm_opt.report.columns import column
from spm_opt.report.planner_style import (
    labelled_handles,
    metric_label,
    new_figure,
    planner_style,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

_SUFFIXES = (
    ("_mm_s", "mm/s"),
    ("_rad_s2", "rad/s²"),
    ("_rad_s3", "rad/s³"),
    ("_rad_s", "rad/s"),
    ("_deg_s", "deg/s"),
    ("_kg_m2", "kg·m²"),
    ("_mm", "mm"),
    ("_kg", "kg"),
    ("_deg", "deg"),
    ("_rpm", "rpm"),
    ("_nm", "N·m"),
    ("_hz", "Hz"),
    ("_s", "s"),
)
"""A parameter key's suffix and the unit it names, longest first."""
_COUNTS = ("flap_landmarks",)
"""Parameters that count."""
LOG_SPAN = 100.0
"""A metric is drawn on a log axis (a histogram's bins log-spaced) when its values are
positive and span more than this factor."""


def _parameter_label(parameter: str) -> str:
    """A parameter's axis label: its key and the unit its suffix names, "count" or "-"."""
    if parameter in _COUNTS:
        return f"{parameter} (count)"
    unit = next((unit for suffix, unit in _SUFFIXES if parameter.endswith(suffix)), "-")
    return f"{parameter} ({unit})"


def _legend_outside(figure: Figure, axis: Axes, below: bool = True) -> None:
    """The figure's legend, from ``axis``'s labelled artists, below the panels (or right
    of them, where a supxlabel is below)."""
    handles, labels = axis.get_legend_handles_labels()
    if below:
        figure.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6))
    else:
        figure.legend(handles, labels, loc="outside right upper")


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
    figure = new_figure((4.2 * min(4, len(metrics) + 1), 3.4 * math.ceil((len(metrics) + 1) / 4)))
    axes = _panels(figure, len(metrics) + 1, 4)
    for index, planner in enumerate(planners):
        mine = medians[medians["planner"] == planner]
        if mine.empty:  # none of its tasks has the parameter
            continue
        style = planner_style(index)
        dots = points[points["planner"] == planner]
        for axis, metric in zip(axes, metrics, strict=False):
            axis.scatter(dots[parameter], dots[metric], s=10, alpha=0.3, color=style["color"], lw=0)
            axis.plot(mine["at"], mine[metric], **style, markersize=4)
        axes[-1].plot(mine["at"], 100 * mine["clean_rate"], **style, ms=4, label=planner)
        axes[-1].plot(mine["at"], 100 * mine["planned_rate"], ":", color=style["color"], lw=1)
    for axis, metric in zip(axes, metrics, strict=False):
        axis.set_ylabel(metric_label(metric))
        if _log_spaced(points[metric].dropna().to_numpy()):
            axis.set_yscale("log")
    axes[-1].set_ylabel("tasks clean (marked), planned (dotted) (%)", fontsize=9)
    axes[-1].set_ylim(-5, 105)
    for axis in axes:
        axis.grid(True, alpha=0.3)
    figure.suptitle(
        f"{name}: key metrics against {parameter} (dots: planned tasks; lines: medians"
        + (f" of {bins} quantile bins)" if bins else ")")
    )
    figure.supxlabel(_parameter_label(parameter))
    _legend_outside(figure, axes[-1], below=False)
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
        over the planned tasks). The colour scale spans every planner's cells, unless the
        planner's own cells all hold one value: then the title says so and the colour bar
        shows that value alone.
    parameters : (str, str)
        The parameters across and up.
    planner, metric, name : str
        The planner drawn, the metric, and the sweep's name for the title.
    labels : (sequence of str, sequence of str)
        The parameters' values as text, across and up.
    """
    import matplotlib as mpl

    mine = cells[cells["planner"] == planner]
    constant = _constant(mine["median"])
    low, high = _colour_range(cells["median"] if constant is None else mine["median"])
    columns, rows = labels
    grid = np.full((len(rows), len(columns)), np.nan)
    figure = new_figure((2.2 + 1.1 * len(columns), 1.8 + 0.8 * len(rows)))
    axis = figure.subplots()
    for cell in mine.itertuples(index=False):
        grid[cell.y, cell.x] = cell.median
        if cell.planned == 0:
            text, shade = "failed", 1.0
        else:
            text = f"{cell.median:.3g}" + ("*" if cell.clean < cell.planned else "")
            shade = (cell.median - low) / (high - low)
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
    bar = figure.colorbar(image, ax=axis, label=metric_label(metric))
    if constant is not None:
        bar.set_ticks([constant], labels=[f"{constant:.4g}"])
    axis.set_xticks(range(len(columns)), list(columns))
    axis.set_yticks(range(len(rows)), list(rows))
    axis.set_xlabel(_parameter_label(parameters[0]))
    axis.set_ylabel(_parameter_label(parameters[1]))
    axis.set_title(
        f"{name}, {planner}: median {column(metric).label}\n"
        + (f"constant: every planned cell {constant:.4g}; " if constant is not None else "")
        + "*: a task of the cell breaks a limit; failed: none planned",
        fontsize=10,
    )
    return figure


def _constant(values: pd.Series) -> float | None:
    """The one value of ``values`` (NaN left out), or None if they hold none or several."""
    finite = values.dropna().unique()
    return float(finite[0]) if len(finite) == 1 else None


def _colour_range(values: pd.Series) -> tuple[float, float]:
    """A colour scale over ``values`` (NaN left out): from the least to the greatest, or,
    if they are one value, a narrow band about it (0.1 % each side, or ±1 about 0)."""
    finite = values.dropna()
    if finite.empty:
        return 0.0, 1.0
    low, high = float(finite.min()), float(finite.max())
    if high > low:
        return low, high
    half = 1e-3 * abs(low) or 1.0
    return low - half, low + half


def flap_robustness(table: pd.DataFrame, flaps: int, name: str) -> Figure:
    """Per planner, the share of the flaps' tasks planned and clean (bars, %, with counts).

    ``table`` has a row per planner, in the order of their colours, indexed by its name:
    columns ``tasks``, ``planned``, ``clean`` (counts) and ``planned_rate``,
    ``clean_rate`` (fractions); ``flaps`` is the number of flaps, for the title.
    """
    import matplotlib as mpl

    figure = new_figure((1.5 + 1.2 * len(table), 4.8))
    axis = figure.subplots()
    at = np.arange(len(table))
    colours = [planner_style(k)["color"] for k in range(len(table))]
    for offset, share, count, alpha in (
        (-0.2, "planned_rate", "planned", 0.45),
        (0.2, "clean_rate", "clean", 1.0),
    ):
        bars = axis.bar(at + offset, 100 * table[share], width=0.4, color=colours, alpha=alpha)
        counts = [f"{k}/{n}" for k, n in zip(table[count], table["tasks"], strict=True)]
        axis.bar_label(bars, counts, fontsize=8)
    axis.set_xticks(at, list(table.index))
    axis.set_ylim(0, 110)
    axis.set_ylabel("tasks (%)")
    axis.grid(True, axis="y", alpha=0.3)
    figure.legend(
        handles=[
            mpl.patches.Patch(color="0.5", alpha=0.45, label="planned (left, pale)"),
            mpl.patches.Patch(color="0.5", label="clean: no limit broken (right)"),
        ],
        loc="outside lower center",
        ncol=2,
        fontsize=8,
    )
    axis.set_title(f"{name}: robustness over {flaps} generated bone flaps", fontsize=10)
    return figure


def flap_rates(
    rates: Mapping[str, pd.DataFrame], planners: Sequence[str], flaps: int, name: str
) -> Figure:
    """A panel per parameter: each planner's share of tasks clean (marked) and planned
    (dotted), %, per value or bin of the parameter. A parameter with as many values as
    there are flaps has one flap per value, where a share is one flap's outcome: its panel
    shows each flap's outcome per planner instead (clean, breaks a limit, failed), and
    says so.

    Parameters
    ----------
    rates : mapping of str to pandas.DataFrame
        Per parameter, a row per group and planner, in the groups' order: columns
        ``group`` (the group's label), ``planner``, ``planned_rate`` and ``clean_rate``
        (fractions).
    planners : sequence of str
        Every planner of the sweep, in the order of their colours.
    flaps : int
        The number of flaps, for the title and to tell a parameter with one flap per value.
    name : str
        The sweep's name, for the title.
    """
    figure = new_figure((4.6 * min(4, len(rates)), 3.8 * math.ceil(len(rates) / 4) + 0.6))
    axes = _panels(figure, len(rates), 4)
    for axis, (parameter, table) in zip(axes, rates.items(), strict=True):
        labels = list(dict.fromkeys(table["group"]))
        at = {label: k for k, label in enumerate(labels)}
        if len(labels) == flaps:
            _outcomes(axis, table, planners, at)
        else:
            _shares(axis, table, planners, at)
        axis.set_xticks(range(len(labels)), labels, rotation=30 if len(labels) > 4 else 0)
        axis.set_xlabel(_parameter_label(parameter))
        axis.grid(True, alpha=0.3)
    figure.suptitle(f"{name}: robustness over {flaps} generated bone flaps, per parameter")
    handles = labelled_handles(axes)
    order = [*planners, *(label for label, _ in _OUTCOMES)]
    labels = sorted(handles, key=order.index)
    figure.legend([handles[k] for k in labels], labels, loc="outside lower center", ncol=6)
    return figure


_OUTCOMES = (
    ("clean", {"marker": "o", "color": "tab:green"}),
    ("breaks a limit", {"marker": "^", "color": "tab:orange"}),
    ("failed", {"marker": "x", "color": "tab:red"}),
)
"""How a flap's outcome is drawn where each value has one flap."""


def _shares(axis: Axes, table: pd.DataFrame, planners: Sequence[str], at: dict) -> None:
    """Each planner's shares of tasks clean (marked) and planned (dotted), %, per group."""
    for index, planner in enumerate(planners):
        mine = table[table["planner"] == planner]
        if mine.empty:  # none of its tasks has the parameter
            continue
        x = [at[label] for label in mine["group"]]
        style = planner_style(index)
        axis.plot(x, 100 * mine["clean_rate"], **style, ms=4, label=planner)
        axis.plot(x, 100 * mine["planned_rate"], ":", color=style["color"], lw=1)
    axis.set_ylim(-5, 105)
    axis.set_ylabel("tasks (%)")
    axis.set_title("tasks clean (marked), planned (dotted)", fontsize=10)


def _outcomes(axis: Axes, table: pd.DataFrame, planners: Sequence[str], at: dict) -> None:
    """Each planner's outcome (a row of marks) on the one flap of each value."""
    for row, planner in enumerate(planners):
        mine = table[table["planner"] == planner]
        outcome = np.where(mine["clean_rate"] > 0, 0, np.where(mine["planned_rate"] > 0, 1, 2))
        x = np.array([at[label] for label in mine["group"]])
        for code, (label, style) in enumerate(_OUTCOMES):
            shown = outcome == code
            if shown.any():
                axis.plot(x[shown], np.full(shown.sum(), row), ls="none", **style, label=label)
    axis.set_yticks(range(len(planners)), list(planners))
    axis.set_ylim(len(planners) - 0.5, -0.5)
    axis.set_title("one flap per value: each mark is one flap, not a rate", fontsize=10)


def histograms(points: pd.DataFrame, planners: Sequence[str], name: str) -> Figure:
    """A panel per metric: each planner's histogram over its planned tasks (shared bins,
    log-spaced on a log axis where the values span more than :data:`LOG_SPAN`).

    ``points`` are the planned tasks: column ``planner`` and one per metric; ``planners``
    every planner of the sweep, in the order of their colours.
    """
    metrics = [m for m in points.columns if m != "planner"]
    figure = new_figure((4.2 * min(4, len(metrics)), 3.4 * math.ceil(len(metrics) / 4) + 0.6))
    axes = _panels(figure, len(metrics), 4)
    for axis, metric in zip(axes, metrics, strict=True):
        values = points[metric].dropna()
        edges = _bins(values.to_numpy())
        for index, planner in enumerate(planners):
            mine = points.loc[points["planner"] == planner, metric].dropna()
            if len(mine):
                style = planner_style(index)
                axis.hist(
                    mine,
                    edges,
                    histtype="step",
                    lw=1.5,
                    color=style["color"],
                    linestyle=style["linestyle"],
                    label=planner,
                )
        if _log_spaced(values.to_numpy()):
            axis.set_xscale("log")
        axis.set_xlabel(metric_label(metric))
        axis.set_ylabel("planned tasks (count)", fontsize=8)
        axis.grid(True, alpha=0.3)
    figure.suptitle(f"{name}: key metrics over the generated bone flaps, per planner")
    _legend_outside(figure, axes[0])
    return figure


def _log_spaced(values: np.ndarray) -> bool:
    """Whether ``values`` are positive and span more than :data:`LOG_SPAN`."""
    return bool(len(values) and values.min() > 0 and values.max() > LOG_SPAN * values.min())


def _bins(values: np.ndarray) -> np.ndarray:
    """Histogram bin edges for ``values``: about √n of them (5–30), log-spaced if
    :func:`_log_spaced`."""
    count = min(30, max(5, int(len(values) ** 0.5)))
    if _log_spaced(values):
        return np.geomspace(values.min(), values.max(), count + 1)
    return np.histogram_bin_edges(values, bins=count)
