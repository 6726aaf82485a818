"""The 3-D review page of a plan: one self-contained HTML file (plotly, its JavaScript
inlined) that opens offline.

It shows the plan in 3-D (:mod:`spm_opt.report.review_figure`): the skull around the flap,
the landmarks, the planned contour, the planned cut coloured by its distance from the
contour, the executed cut of a log, and the robot (arcs, platforms, tool) at a time a
slider and a play button choose. Beside the plot, the judge's verdicts
(:mod:`spm_opt.report.review_verdict`): the plan's, by ``spm-opt evaluate`` of the plan,
and the run's, by ``spm-opt evaluate`` of its log, each with the tube it is judged against,
its headline figures and its violations, which the plot marks on the cut; the same verdicts
as JSON in ``<script type="application/json" id="verdict">``.

What it is given is checked as ``spm-opt evaluate`` and ``spm-opt execute`` check it
(:func:`spm_opt.report.review_inputs.review_inputs`): a plan or a log made for another
problem is drawn only when asked for, and the page then says so above everything else.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.base.errors import InputError, require
from spm_opt.report.review_figure import BACKGROUND, review_figure
from spm_opt.report.review_scene import review_scene
from spm_opt.report.review_verdict import (
    Judged,
    judged_cuts,
    tube_text,
    verdict_json,
    verdict_line,
)

if TYPE_CHECKING:
    from spm_opt.judge.report import Report
    from spm_opt.problem.problem import Problem
    from spm_opt.report.review_inputs import ReviewInputs
    from spm_opt.skull.surface import Skull

ASIDE_WIDTH = "430px"
"""The width (CSS) of the column of figures and verdicts at the page's left; the plot
fills the rest of the window."""


def review_page(
    problem: Problem, skull: Skull, given: ReviewInputs, report: Report | None = None
) -> str:
    """The review page, a whole HTML document (about 5 MB, plotly's JavaScript inlined).

    Parameters
    ----------
    problem : Problem
    skull : Skull
        The skull the cut lies on (its outer mesh, or its surface without one).
    given : ReviewInputs
        The plan, and a log with the judge's reports of it
        (:func:`~spm_opt.report.review_inputs.review_inputs`); its
        warnings are shown above everything else.
    report : Report, optional
        The plan's report; by default ``evaluate(problem, trajectory)``.
    """
    from spm_opt.judge.evaluate import evaluate

    require("plotly", "the review page")
    if (given.log is None) != (given.run is None):
        raise InputError("given: a log and the judge's reports of it go together")
    trajectory = given.trajectory
    report = evaluate(problem, trajectory) if report is None else report
    cuts = judged_cuts(problem, report, given.run, given.predicted)
    scene = review_scene(problem, skull, trajectory, given.log, given.predicted)
    figure = review_figure(problem, scene, trajectory, cuts)
    plot = figure.to_html(
        include_plotlyjs=True,
        full_html=False,
        auto_play=False,
        config={"responsive": True},
        default_height="100%",
    )
    title = f"{problem.name}: {report.planner or 'plan'}"
    return _DOCUMENT.format(
        title=html.escape(title),
        background=BACKGROUND,
        warnings="".join(
            f'<p class="warning">Warning: {html.escape(w)}; reviewed under '
            f"{html.escape(problem.name)}'s limits.</p>\n"
            for w in given.warnings
        ),
        table=_table(plan_rows(report, skull)),
        verdict=_verdict_table(cuts),
        violations="\n".join(_violations(cut) for cut in cuts),
        verdict_json=verdict_json(cuts),
        aside_width=ASIDE_WIDTH,
        plot=plot,
    )


def plan_rows(report: Report, skull: Skull | None = None) -> list[tuple[str, str]]:
    """The plan's figures the page's first table shows, as (what, value with its unit):
    the report's, and of a skull from imaging its registration's error, its largest
    fiducial residual and the landmarks' moves onto it."""
    rows = [
        ("planner", report.planner or "(unknown)"),
        ("duration", f"{report.duration_s:.2f} s"),
        ("over the duration's lower bound", f"{report.duration_over_lower_bound:.3f}"),
    ]
    if skull is not None and skull.registration_rms_mm is not None:
        rows.append(("registration RMS error", f"{skull.registration_rms_mm:.3f} mm"))
    if skull is not None and skull.fiducial_residuals_mm is not None:
        largest = float(np.max(skull.fiducial_residuals_mm))
        rows.append(("largest fiducial residual", f"{largest:.3f} mm"))
    if skull is not None and skull.landmark_shifts_mm is not None:
        moved = float(np.max(np.abs(skull.landmark_shifts_mm)))
        rows.append(("landmarks moved onto the mesh", f"≤ {moved:.3f} mm"))
    return rows


def cut_rows(cut: Judged) -> list[tuple[str, str]]:
    """A judged cut's figures, from its report, as (what, value with its unit): one row of
    the page's verdict table."""
    report = cut.report
    rows = [
        ("judged in the tube", tube_text(cut)),
        ("max off the contour", f"{report.max_contour_deviation_mm:.3f} mm"),
        ("RMS off the contour", f"{report.rms_contour_deviation_mm:.3f} mm"),
        ("max tool speed", f"{report.max_tool_speed_mm_s:.2f} mm/s"),
        ("contour never cut inside the tube", f"{report.coverage_gap_mm:.2f} mm"),
        ("max landmark error", f"{report.max_landmark_error_mm:.3f} mm"),
        ("max tool incidence", _shown(report.max_tool_incidence_deg, "{:.1f}°")),
        ("max depth speed", _shown(report.max_depth_speed_mm_s, "{:.2f} mm/s")),
        ("max depth acceleration", _shown(report.max_depth_acceleration_mm_s2, "{:.1f} mm/s²")),
        ("violations", str(len(report.violations))),
        ("run completed", _completed(cut)),
    ]
    return rows


def _completed(cut: Judged) -> str:
    if not cut.executed:
        return "—"
    return "yes" if getattr(cut.report, "completed", True) else "no"


def _shown(value: float | None, form: str) -> str:
    return "—" if value is None else form.format(value)


def _table(rows: list[tuple[str, str]]) -> str:
    """The plan's figures, a row each: what, then its value."""
    body = "".join(
        f"<tr><th>{html.escape(what)}</th><td>{html.escape(value)}</td></tr>\n"
        for what, value in rows
    )
    return f'<table class="plan">\n{body}</table>'


def _verdict_table(cuts: Sequence[Judged]) -> str:
    """The judged cuts' figures: a column per cut, a row per figure."""
    columns = [dict(cut_rows(cut)) for cut in cuts]
    heads = "".join(
        f'<th class="{"fail" if cut.failed else "pass"}">{html.escape(cut.label)}</th>'
        for cut in cuts
    )
    body = "".join(
        f"<tr><th>{html.escape(what)}</th>"
        + "".join(f"<td>{html.escape(column[what])}</td>" for column in columns)
        + "</tr>\n"
        for what in columns[0]
    )
    return f'<table class="verdict">\n<tr><th></th>{heads}</tr>\n{body}</table>'


def _violations(cut: Judged) -> str:
    """The judge's verdict on a cut in a sentence, then its violations, each a line."""
    line = f'<p class="{"fail" if cut.failed else "pass"}">{html.escape(verdict_line(cut))}</p>'
    if not cut.report.violations:
        return line
    items = "\n".join(f"<li>{html.escape(str(v))}</li>" for v in cut.report.violations)
    return f"{line}\n<ul>\n{items}\n</ul>"


_DOCUMENT = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ background: {background}; font-family: sans-serif; margin: 0; display: flex;
  height: 100vh; }}
aside {{ flex: 0 0 {aside_width}; overflow-y: auto; padding: 12px 14px;
  box-sizing: border-box; border-right: 1px solid #ddd; }}
main {{ flex: 1 1 auto; min-width: 0; height: 100vh; }}
main > div {{ height: 100%; }}
h1 {{ font-size: 17px; margin: 0 0 8px; }}
table {{ border-collapse: collapse; font-size: 12px; margin: 0 0 8px; }}
th, td {{ border: 1px solid #ccc; padding: 2px 6px; }}
th {{ font-weight: normal; color: #444; text-align: left; }}
td {{ text-align: center; }}
.fail {{ color: #b00000; font-weight: bold; }}
p, ul {{ font-size: 12px; margin: 6px 0; }}
ul {{ padding-left: 18px; }}
p.warning {{ color: #b00000; font-weight: bold; }}
</style>
</head>
<body>
<aside>
<h1>{title}</h1>
{warnings}{table}
{verdict}
{violations}
<script type="application/json" id="verdict">
{verdict_json}
</script>
</aside>
<main>
{plot}
</main>
</body>
</html>
"""
