"""How the comparison's and the sweeps' figures draw planners and name metrics: one colour,
line style and marker per planner by its place in the list, a metric's axis label with its
unit, the contour tubes' words, and one legend gathered from a figure's panels."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, NamedTuple

from spm_opt.judge.limits import contour_tube
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem
from spm_opt.report.columns import column

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

COLOURS = tuple(f"C{k}" for k in range(10))
LINES = ("-", "--", "-.", ":")
MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*")
_UNITLESS = {"violation_count": "count"}
"""The unit in the axis label of a metric without one (any other: "-", a ratio)."""


def new_figure(size: tuple[float, float]) -> Figure:
    """An empty figure of ``size`` (in), laid out by matplotlib's constrained layout."""
    from matplotlib.figure import Figure

    return Figure(figsize=size, layout="constrained")


def planner_style(index: int) -> dict[str, object]:
    """The ``index``-th planner's colour, line style and marker."""
    return {
        "color": COLOURS[index % len(COLOURS)],
        "linestyle": LINES[index % len(LINES)],
        "marker": MARKERS[index % len(MARKERS)],
    }


def metric_label(name: str) -> str:
    """A metric's axis label with its unit: "(-)" for a ratio, "(count)" for a count."""
    shown = column(name)
    return shown.label if shown.unit else f"{shown.label} ({_UNITLESS.get(name, '-')})"


def labelled_handles(axes: Iterable[Axes]) -> dict[str, Artist]:
    """Every labelled artist of ``axes`` by its label, each label once (the first seen),
    for one legend of the whole figure."""
    handles: dict[str, Artist] = {}
    for axis in axes:
        for handle, label in zip(*axis.get_legend_handles_labels(), strict=True):
            handles.setdefault(label, handle)
    return handles


class Limit(NamedTuple):
    """A limit as a figure draws it and a summary writes it: its value (in the unit of the
    quantity it limits) and its words."""

    value: float
    words: str


def contour_tubes(problem: Problem) -> list[Limit]:
    """The contour tubes a cut is judged against, mm, smaller first: a plan's (the
    contour tolerance less the execution reserve) and an executed cut's (the whole
    tolerance); one tube when no reserve is kept, none when the problem sets no tolerance."""
    executed = contour_tube(problem, executed=True)
    if executed is None:
        return []
    whole, plan = executed / MM, contour_tube(problem) / MM  # type: ignore[operator]
    if problem.limits.execution_reserve == 0.0:
        return [Limit(whole, f"tube {whole:.4g} mm (a plan's and an executed cut's)")]
    kept = problem.limits.execution_reserve / MM
    return [
        Limit(
            plan,
            f"plan's tube {plan:.4g} mm ({whole:.4g} mm less {kept:.4g} mm kept for execution)",
        ),
        Limit(whole, f"executed cut's tube {whole:.4g} mm"),
    ]
