"""The rules every figure the commands write keeps, and the checker that finds the broken ones.

    from spm_opt.report.figure_rules import figure_faults, mark_top_view
    mark_top_view(axis)               # a top view: marked, with the anterior arrow drawn
    assert figure_faults(figure) == []

The rules, one line of :func:`figure_faults` per break:

1. Every axis that shows numbers is labelled with its unit in parentheses: "(mm)", "(N·m)",
   "(%)", "(count)", "(-)" for a ratio. An axis that shows names only (planners) needs
   none; a colour bar's long axis counts; the figure's supxlabel and supylabel label the
   panels without a label of their own.
2. A title: the figure's suptitle, or each panel's own.
3. No legend covers plotted data of any panel (lines, markers, bars, patches, images) in
   display coordinates. Lines and spans across a whole panel (``axhline``, ``axvspan``:
   references, not data) do not count.
4. Every top view (the skull or the cut seen from above, x–y in mm) shows the anterior
   direction: an artist whose gid is :data:`ANTERIOR`. A panel is a top view when its gid
   is :data:`TOP_VIEW` or it is labelled x (mm) across and y (mm) up.

Which way is anterior is stated neither in the paper's text nor in the code: the figures
take −x, as docs/conventions.md does (:data:`ANTERIOR_XY`), the side of the vertex A1 the
paper's bone flap lies on (A2–A4 at x < 0), in what the robot file calls the robot's
frontal workspace. The arrow says the direction is assumed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.axis import Axis
    from matplotlib.colorbar import Colorbar
    from matplotlib.figure import Figure
    from matplotlib.transforms import Bbox

TOP_VIEW = "top-view"
"""The gid of a top view's axes."""
ANTERIOR = "anterior"
"""The gid of the anterior marker on a top view."""
ANTERIOR_XY = (-1.0, 0.0)
"""The anterior direction in the robot's x–y plane (assumed: see the module's docstring)."""
ANTERIOR_LABEL = "anterior (assumed: −x)"
"""The anterior arrow's words."""

_ATOMS = ("mm", "µm", "μm", "ms", "mA", "min", "Hz", "kg", "deg", "rad", "rpm", "Pa")
_ATOMS += ("m", "s", "h", "g", "N", "J", "W", "A", "V", "K", "°", "1")
_ATOM = "(?:" + "|".join(_ATOMS) + ")(?:[⁻¹²³⁴]+|\\^-?\\d+)?"
_UNIT = re.compile(rf"\((?:-|%|count|dimensionless|{_ATOM}(?:\s*[·*/]\s*{_ATOM})*)\)")
_MATHTEXT = re.compile(r"\\[A-Za-z]+")
_LETTER = re.compile(r"[A-DF-Za-df-z]")


def has_unit(label: str) -> bool:
    """Whether an axis label carries a unit in parentheses: "speed (mm/s)", "ratio (-)"."""
    return _UNIT.search(label) is not None


def mark_top_view(axis: Axes) -> None:
    """Mark ``axis`` a top view (x–y, mm) and draw the anterior arrow where the plot holds
    the fewest of the points drawn so far (draw it after the data)."""
    axis.set_gid(TOP_VIEW)
    direction = np.asarray(ANTERIOR_XY) / np.hypot(*ANTERIOR_XY)
    tail = _emptiest_place(axis)
    axis.annotate(
        ANTERIOR_LABEL,
        xy=tuple(tail + 0.12 * direction),
        xytext=tuple(tail),
        xycoords="axes fraction",
        ha="left" if direction[0] <= 0 else "right",
        va="center",
        fontsize=8,
        arrowprops={"arrowstyle": "-|>", "color": "black"},
        gid=ANTERIOR,
    )


def _emptiest_place(axis: Axes) -> np.ndarray:
    """Where the arrow's tail goes (axes fraction): the place, of a grid from the upper left
    corner on, whose box (0.14 left of it to 0.32 right, ±0.05 up and down) holds the
    fewest of the points of ``axis``'s lines and markers; the first such place wins ties."""
    axis.autoscale_view()
    points = [line.get_xydata() for line in axis.lines]
    points += [collection.get_offsets() for collection in axis.collections]
    xy = np.concatenate([np.zeros((0, 2)), *(np.reshape(p, (-1, 2)) for p in points)])
    xy = axis.transLimits.transform(xy)
    places = [np.array([x, y]) for y in np.linspace(0.93, 0.07, 9) for x in (0.16, 0.4, 0.64)]

    def count(place: np.ndarray) -> int:
        across = (xy[:, 0] > place[0] - 0.14) & (xy[:, 0] < place[0] + 0.32)
        return int(np.sum(across & (np.abs(xy[:, 1] - place[1]) < 0.05)))

    return min(places, key=count)


def figure_faults(figure: Figure) -> list[str]:
    """Every rule of the module's docstring ``figure`` breaks, one line each ([]: none).

    Draws the figure (without rendering) to place its legends and lay it out."""
    figure.draw_without_rendering()
    colour_bars = {id(bar.ax): bar for bar in _colour_bars(figure)}
    panels = [ax for ax in figure.axes if ax.get_visible() and id(ax) not in colour_bars]
    faults = [
        f"colour bar of {_name(bar.mappable.axes)}: label {label!r} has no unit"
        for bar in colour_bars.values()
        if not has_unit(label := bar.long_axis.get_label_text())
    ]
    for panel in panels:
        faults += _unit_faults(figure, panel)
    faults += _title_faults(figure, panels)
    faults += _legend_faults(figure, panels)
    faults += [
        f"{_name(panel)}: a top view without the anterior marker (gid {ANTERIOR!r})"
        for panel in panels
        if _is_top_view(panel) and not _has_anterior(panel)
    ]
    return faults


def _colour_bars(figure: Figure) -> Iterator[Colorbar]:
    for axis in figure.axes:
        for mappable in [*axis.images, *axis.collections]:
            if getattr(mappable, "colorbar", None) is not None:
                yield mappable.colorbar


def _name(panel: Axes) -> str:
    """A panel as a fault names it: its index and title."""
    index = panel.figure.axes.index(panel)
    title = _title(panel)
    return f"panel {index}" + (f" ({title!r})" if title else "")


def _title(panel: Axes) -> str:
    return " ".join(t for loc in ("left", "center", "right") if (t := panel.get_title(loc)))


def _axes_of(panel: Axes) -> list[tuple[str, Axis]]:
    names = ("x", "y", "z") if hasattr(panel, "zaxis") else ("x", "y")
    return [(name, getattr(panel, f"{name}axis")) for name in names]


def _numeric(text: str) -> bool:
    """Whether a tick label is a number or a range of numbers ("0.25", "10⁻³", "20–27.5")."""
    plain = _MATHTEXT.sub("", text)
    return any(c.isdigit() for c in plain) and not _LETTER.search(plain)


def _unit_faults(figure: Figure, panel: Axes) -> list[str]:
    faults = []
    shared = {"x": figure.get_supxlabel(), "y": figure.get_supylabel()}
    for name, axis in _axes_of(panel):
        if not axis.get_visible():
            continue
        if not any(_numeric(label.get_text()) for label in axis.get_ticklabels()):
            continue  # no numbers shown: names, or tick labels left to a shared axis
        label = axis.get_label_text() or shared.get(name, "")
        if not label:
            faults.append(f"{_name(panel)}: the {name} axis shows numbers but has no label")
        elif not has_unit(label):
            faults.append(f"{_name(panel)}: the {name} axis label {label!r} has no unit")
    return faults


def _title_faults(figure: Figure, panels: list[Axes]) -> list[str]:
    if figure.get_suptitle() or not panels:
        return []
    places = set()
    faults = []
    for panel in panels:
        place = tuple(np.round(panel.get_position().bounds, 6))
        if place in places:
            continue  # a twin of a panel already seen
        places.add(place)
        if not _title(panel):
            faults.append(f"{_name(panel)}: no title (and the figure has no suptitle)")
    return faults


def _legend_faults(figure: Figure, panels: list[Axes]) -> list[str]:
    legends = [(_name(p), p.get_legend()) for p in panels if p.get_legend() is not None]
    legends += [("the figure", legend) for legend in figure.legends]
    faults = []
    for owner, legend in legends:
        if not legend.get_visible():
            continue
        box = legend.get_window_extent()
        covered = [_name(p) for p in panels if _covers(box, p)]
        if covered:
            faults.append(f"legend of {owner} covers data of {', '.join(covered)}")
    return faults


def _covers(box: Bbox, panel: Axes) -> bool:
    """Whether ``box`` (display coordinates) overlaps anything drawn as data in ``panel``."""
    return any(_overlaps(box, points, joined, filled) for points, joined, filled in _drawn(panel))


def _drawn(panel: Axes) -> Iterator[tuple[np.ndarray, bool, bool]]:
    """The panel's data in display coordinates: (vertices (n, 2), joined by lines, filled)."""
    from matplotlib.collections import PathCollection

    for line in panel.lines:
        if line.get_visible() and _in_data(line.get_transform(), panel):
            joined = line.get_linestyle() not in ("None", "", " ")
            yield line.get_transform().transform(line.get_xydata()), joined, False
    for collection in panel.collections:
        if not collection.get_visible():
            continue
        if isinstance(collection, PathCollection):
            transform = collection.get_offset_transform()
            if _in_data(transform, panel):
                yield transform.transform(collection.get_offsets()), False, False
        elif _in_data(collection.get_transform(), panel):
            filled = _filled(collection.get_facecolor())
            for path in collection.get_paths():
                for polygon in path.to_polygons(collection.get_transform(), closed_only=False):
                    yield polygon, True, filled
    for patch in panel.patches:
        if patch.get_visible() and _in_data(patch.get_transform(), panel):
            filled = patch.get_fill() and _filled(patch.get_facecolor())
            for polygon in patch.get_path().to_polygons(patch.get_transform(), closed_only=False):
                yield polygon, True, filled
    for image in panel.images:
        if image.get_visible():
            yield image.get_window_extent().corners()[[0, 1, 3, 2, 0]], True, True


def _in_data(transform: object, panel: Axes) -> bool:
    """Whether an artist's transform maps data coordinates in both directions (not an
    ``axhline``'s or an ``axvspan``'s blend of data and axes coordinates)."""
    return transform.contains_branch(panel.transData)  # type: ignore[attr-defined]


def _filled(colours: np.ndarray) -> bool:
    colours = np.asarray(colours)
    return bool(colours.size and np.any(colours.reshape(-1, 4)[:, 3] > 0))


def _overlaps(box: Bbox, points: np.ndarray, joined: bool, filled: bool) -> bool:
    """Whether ``box`` holds a point, crosses a segment between consecutive points (if
    ``joined``) or lies inside the polygon (if ``filled``)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    (x0, y0), (x1, y1) = box.get_points()
    finite = np.all(np.isfinite(points), axis=1)
    inside = (points[:, 0] > x0) & (points[:, 0] < x1) & (points[:, 1] > y0) & (points[:, 1] < y1)
    if np.any(inside & finite):
        return True
    if joined and len(points) > 1:
        pair = finite[:-1] & finite[1:]
        if _crosses((x0, y0, x1, y1), points[:-1][pair], points[1:][pair]):
            return True
    if filled and len(points) > 2 and np.all(finite):
        from matplotlib.path import Path

        return bool(Path(points).contains_point(((x0 + x1) / 2, (y0 + y1) / 2)))
    return False


def _crosses(box: tuple[float, float, float, float], a: np.ndarray, b: np.ndarray) -> bool:
    """Whether any segment a→b (each (n, 2)) passes through the open box (Liang–Barsky)."""
    x0, y0, x1, y1 = box
    d = b - a
    low, high = np.zeros(len(a)), np.ones(len(a))
    missed = np.zeros(len(a), dtype=bool)
    for p, q in (
        (-d[:, 0], a[:, 0] - x0),
        (d[:, 0], x1 - a[:, 0]),
        (-d[:, 1], a[:, 1] - y0),
        (d[:, 1], y1 - a[:, 1]),
    ):
        parallel = p == 0.0
        missed |= parallel & (q <= 0.0)
        ratio = np.divide(q, p, out=np.zeros_like(q), where=~parallel)
        low = np.where(p < 0.0, np.maximum(low, ratio), low)
        high = np.where(p > 0.0, np.minimum(high, ratio), high)
    return bool(np.any(~missed & (low < high)))


def _is_top_view(panel: Axes) -> bool:
    if panel.get_gid() == TOP_VIEW:
        return True
    if hasattr(panel, "zaxis"):
        return False
    across, up = panel.get_xlabel(), panel.get_ylabel()
    return bool(re.match(r"x\b.*\(mm\)", across) and re.match(r"y\b.*\(mm\)", up))


def _has_anterior(panel: Axes) -> bool:
    return any(child.get_gid() == ANTERIOR for child in panel.get_children())
