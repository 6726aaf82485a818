"""A sweep's results: ``DIR/results.jsonl`` read into a table, and the sweep's report.

    from spm_opt.studies.sweep.results import load_sweep, write_sweep_report
    frame = load_sweep("runs/friction_payload")         # one row per finished task
    paths = write_sweep_report("runs/friction_payload")

The report goes beside the results, all files or none: ``results.parquet`` and
``results.csv`` (the table), ``summary.md`` (counts, robustness per planner, the commonest
failures and violations, the medians per value of every swept parameter) and the figures
(:func:`sweep_figures`: the tables here, drawn by :mod:`spm_opt.studies.sweep.results_figures`).

A task is *planned* when its status is not "failed" and *clean* when it is "ok" (planned
with no limit violated); the metrics' medians are over the planned tasks.
"""

from __future__ import annotations

import io
import json
import logging
import math
import re
from collections.abc import Collection, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from spm_opt.base.errors import InputError
from spm_opt.base.files import write_atomically
from spm_opt.base.input_limits import excerpt
from spm_opt.base.markdown import markdown_table
from spm_opt.report.columns import COLUMNS, column
from spm_opt.studies.sweep import results_figures as draw
from spm_opt.studies.sweep.results_file import RESULTS_FILE

if TYPE_CHECKING:
    from matplotlib.figure import Figure

_LOG = logging.getLogger(__name__)

_TEXT = ("status", "violations", "error", "failure")
NUMERIC_COLUMNS = tuple(c for c in COLUMNS if c not in ("planner", *_TEXT))
"""The comparison's numeric columns: a number or null in every row."""

METRICS = (
    "duration_s",
    "duration_over_lower_bound",
    "max_contour_deviation_mm",
    "max_tool_speed_mm_s",
    "peak_torque_nm",
    "effort_n2m2s",
    "wall_time_s",
)
"""The key metrics the summary and the figures show, headed and labelled as
:func:`spm_opt.report.columns.column` says; ``peak_torque_nm`` is the larger of the two
joints' peak torques."""

FLAP = "flap"
"""The parameter naming a generated bone flap (an index: never an axis)."""
MAX_LEVELS = 12
"""A swept parameter with at most this many values is tabulated and drawn per value; one
with more (a random range, flap sizes) per quantile bin."""
BINS = 5
"""Quantile bins of a parameter with more than :data:`MAX_LEVELS` values."""
_FAILURES_SHOWN = 10


def load_sweep(directory: str | Path) -> pd.DataFrame:
    """Read a sweep's ``results.jsonl``: one row per task.

    Parameters
    ----------
    directory : str or Path
        The sweep's directory, holding ``results.jsonl``.

    Returns
    -------
    pandas.DataFrame
        Columns ``key``, ``sweep``, ``planner``, then one column per parameter named by its
        key (``robot.friction.mu``; NaN where a task lacks it), then every column of
        :data:`spm_opt.report.columns.COLUMNS` (NaN, or "" for text, where a row lacks it),
        ``failure`` ("machine" or "result" for a failed task, else ""), then any other field
        (``worker``, ``finished_at``...). A task written twice (run again after it failed)
        is its newest row, the file's last of its key. ``frame.attrs["parameters"]`` lists
        the parameter columns.

    Raises
    ------
    InputError
        No such directory or file, or a line that is not a task's row (its number named).
        A torn last line (text after the last newline, left by a crash while it was
        written) is ignored and logged, as the runner cuts it off before resuming.
    """
    path = Path(directory) / RESULTS_FILE
    if not Path(directory).is_dir():
        raise InputError(f"{directory}: no such sweep directory")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file (has the sweep finished a task?)") from None
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"{path}: cannot be read ({error})") from None
    complete, _, torn = text.rpartition("\n")
    lines = complete.split("\n")
    if torn:
        _LOG.warning("%s, line %d: torn last line ignored", path, len(lines) + bool(complete))
    rows: list[dict[str, Any]] = []
    parameters: dict[str, None] = {}  # ordered as first seen
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as error:
            raise InputError(f"{path}, line {number}: not valid JSON ({error.msg})") from None
        rows.append(_checked(row, f"{path}, line {number}"))
        parameters.update(dict.fromkeys(rows[-1]["parameters"]))
    flat = [{**row.pop("parameters"), **row} for row in rows]
    known = ["key", "sweep", "planner", *parameters, *COLUMNS, "failure"]
    others = {name: None for row in flat for name in row if name not in known}
    frame = pd.DataFrame(flat, columns=list(dict.fromkeys([*known, *others])))
    frame = frame.drop_duplicates("key", keep="last").reset_index(drop=True)
    for name in NUMERIC_COLUMNS:
        frame[name] = frame[name].astype(float)
    for name in _TEXT:
        frame[name] = frame[name].astype("str").fillna("")
    frame.attrs["parameters"] = list(parameters)
    return frame


def _checked(row: Any, where: str) -> dict[str, Any]:
    """The row if it is a task's: an object with text key, planner and status, an object of
    parameters not named like a field, and numbers (or null) for the numeric columns."""
    if not isinstance(row, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(row).__name__}")
    for name in ("key", "planner", "status"):
        if not isinstance(row.get(name), str):
            raise InputError(f"{where}: {name!r} must be a string, got {excerpt(row.get(name))}")
    parameters = row.setdefault("parameters", {})
    if not isinstance(parameters, dict):
        raise InputError(f"{where}: 'parameters' must be an object, got {excerpt(parameters)}")
    for name in parameters:
        if name in row or name in COLUMNS or name == "failure":
            raise InputError(f"{where}: parameter {name!r} has the name of a field")
    for name in NUMERIC_COLUMNS:
        value = row.get(name)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise InputError(f"{where}: {name!r} must be a number or null, got {excerpt(value)}")
    return row


def write_sweep_report(
    directory: str | Path, title: str | None = None, keys: Collection[str] | None = None
) -> list[Path]:
    """Write a sweep's table, summary and figures into its directory, all or none.

    Parameters
    ----------
    directory : str or Path
        The sweep's directory, holding ``results.jsonl``.
    title : str, optional
        The summary's heading; by default "Sweep <name>".
    keys : collection of str, optional
        The keys of the sweep's current tasks: the table, the summary and the figures show
        their rows alone, and the summary counts the others, stale (another specification,
        or another version of the code). By default every row.

    Returns
    -------
    list of Path
        Every file written, sorted: ``results.parquet``, ``results.csv``, ``summary.md``
        and the figures (see :func:`sweep_figures`).

    Raises
    ------
    InputError
        As :func:`load_sweep`, or the sweep has no finished (current) task yet.
    """
    from spm_opt.report.plots import to_png

    directory = Path(directory)
    frame = load_sweep(directory)
    current = frame["key"].isin(set(keys)) if keys is not None else frame["key"].notna()
    stale = int((~current).sum())
    frame = frame[current].reset_index(drop=True)
    if frame.empty:
        raise InputError(
            f"{directory / RESULTS_FILE}: no finished task to report on"
            + (f" ({stale} stale rows)" if stale else "")
        )
    name = ", ".join(str(s) for s in frame["sweep"].dropna().unique()) or directory.name
    data = with_metrics(frame)
    parameters = frame.attrs["parameters"]
    figures = {
        directory / file: to_png(figure) for file, figure in sweep_figures(data, parameters, name)
    }
    parquet = io.BytesIO()
    frame.to_parquet(parquet, index=False)
    contents: dict[Path, str | bytes] = {
        directory / "results.parquet": parquet.getvalue(),
        directory / "results.csv": frame.to_csv(index=False),
        directory / "summary.md": sweep_markdown(
            data, parameters, title or f"Sweep {name}", [path.name for path in figures], stale
        ),
        **figures,
    }
    write_atomically(contents)
    return sorted(contents)


def sweep_figures(
    data: pd.DataFrame, parameters: Sequence[str], name: str
) -> Iterator[tuple[str, Figure]]:
    """Every figure of a sweep, as (file name, figure).

    Parameters
    ----------
    data : pandas.DataFrame
        The sweep's table with its key metrics (:func:`with_metrics`).
    parameters : sequence of str
        Its parameter columns.
    name : str
        The sweep's name, for the titles.

    Yields
    ------
    (str, Figure)
        ``metrics_vs_<parameter>.png`` for each swept numeric parameter (the key metrics
        against it); ``heatmap_<planner>_<metric>.png`` for each planner and key metric
        when exactly two parameters are swept, each over at most :data:`MAX_LEVELS`
        values; ``flap_robustness.png`` and ``flap_histograms.png`` when the sweep has
        generated flaps, and ``flap_robustness_by_parameter.png`` (the rates per value or
        bin of each swept parameter: flap size, landmark count, drawn limits) when it also
        sweeps a parameter. Names are filesystem-safe (:func:`safe_name`).
    """
    metrics = shown_metrics(data)
    swept = swept_parameters(data, parameters)
    planners = list(planner_order(data).cat.categories)
    for parameter in swept:
        yield f"metrics_vs_{safe_name(parameter)}.png", _against(data, parameter, metrics, name)
    if len(swept) == 2 and all(data[p].nunique() <= MAX_LEVELS for p in swept):
        grid = (swept[0], swept[1])
        cells = {metric: _cells(data, grid, metric) for metric in metrics}
        across, up = ([level_label(v) for v in sorted(data[p].dropna().unique())] for p in grid)
        for planner in planners:
            for metric in metrics:
                figure = draw.heatmap(cells[metric], grid, planner, metric, name, (across, up))
                yield f"heatmap_{safe_name(planner)}_{metric}.png", figure
    if FLAP in parameters:
        table = robustness(data, [planner_order(data)], [])
        yield "flap_robustness.png", draw.flap_robustness(table, data[FLAP].nunique(), name)
        if swept:
            rates = {parameter: _rates(data, parameter) for parameter in swept}
            figure = draw.flap_rates(rates, planners, data[FLAP].nunique(), name)
            yield "flap_robustness_by_parameter.png", figure
        if metrics:
            points = data.loc[data["status"] != "failed", ["planner", *metrics]]
            yield "flap_histograms.png", draw.histograms(points, planners, name)


def safe_name(text: str) -> str:
    """``robot.friction.mu`` → ``robot_friction_mu``: letters, digits, "-" and "_" only."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_") or "_"


def _against(data: pd.DataFrame, parameter: str, metrics: Sequence[str], name: str) -> Figure:
    """The key metrics against ``parameter``: the planned tasks, and per planner the
    medians per value (or quantile bin) over every other parameter."""
    level = groups(data[parameter])
    planner = planner_order(data)
    medians = robustness(data, [level, planner], metrics)
    medians["at"] = data[parameter].groupby([level, planner], observed=True).median()
    points = data.loc[data["status"] != "failed", ["planner", parameter, *metrics]]
    binned = isinstance(level.dtype, pd.CategoricalDtype)
    return draw.against(
        points,
        medians.reset_index(level=-1),
        parameter,
        list(planner.cat.categories),
        name,
        level.nunique() if binned else None,
    )


def _rates(data: pd.DataFrame, parameter: str) -> pd.DataFrame:
    """Per group of ``parameter`` (value or quantile bin) and planner, in the groups' order:
    columns ``group`` (its label), ``planner``, ``tasks``, ``planned``, ``clean`` (counts),
    ``planned_rate`` and ``clean_rate`` (fractions)."""
    level = groups(data[parameter]).rename("group")
    table = robustness(data, [level, planner_order(data)], []).reset_index()
    table["group"] = [level_label(value) for value in table["group"]]
    return table


def _cells(data: pd.DataFrame, grid: tuple[str, str], metric: str) -> pd.DataFrame:
    """The cells of a heat map of ``metric`` over two parameters, for every planner (see
    :func:`spm_opt.studies.sweep.results_figures.heatmap`)."""
    x, y = grid
    table = robustness(data, [data[x], data[y], planner_order(data)], [metric]).reset_index()
    index = {p: {v: k for k, v in enumerate(sorted(data[p].dropna().unique()))} for p in grid}
    return pd.DataFrame(
        {
            "x": table[x].map(index[x]),
            "y": table[y].map(index[y]),
            "planner": table["planner"],
            "planned": table["planned"],
            "clean": table["clean"],
            "median": table[metric],
        }
    )


def with_metrics(frame: pd.DataFrame) -> pd.DataFrame:
    """A copy of a sweep's table with ``peak_torque_nm`` (the larger joint's peak torque)
    and the attrs kept."""
    data = frame.copy()
    data["peak_torque_nm"] = frame[["peak_torque_1_nm", "peak_torque_2_nm"]].max(axis=1)
    return data


def shown_metrics(data: pd.DataFrame) -> list[str]:
    """The key metrics (:data:`METRICS`) that some task has a value of."""
    return [name for name in METRICS if data[name].notna().any()]


def swept_parameters(data: pd.DataFrame, parameters: Sequence[str]) -> list[str]:
    """The numeric parameters that take at least two values (never ``flap``, an index)."""
    return [
        name
        for name in parameters
        if name != FLAP
        and pd.api.types.is_numeric_dtype(data[name])
        and not pd.api.types.is_bool_dtype(data[name])
        and data[name].nunique() >= 2
    ]


def groups(values: pd.Series) -> pd.Series:
    """Each task's group along a swept parameter: its value if the parameter takes at most
    :data:`MAX_LEVELS` values, else its quantile bin, a category named by the least and
    the greatest value in it (``20.1–27.5``)."""
    if values.nunique() <= MAX_LEVELS:
        return values
    bins = pd.qcut(values, BINS, duplicates="drop").cat.remove_unused_categories()
    span = values.groupby(bins, observed=True).agg(["min", "max"]).to_numpy()
    return bins.cat.rename_categories([f"{low:.4g}–{high:.4g}" for low, high in span])


def robustness(data: pd.DataFrame, by: Sequence[pd.Series], metrics: Sequence[str]) -> pd.DataFrame:
    """Per group of ``by``: tasks, planned and clean (counts), their rates (fractions), and
    the median of each metric over the planned tasks."""
    planned = data["status"] != "failed"
    table = pd.DataFrame(
        {"tasks": 1, "planned": planned, "clean": data["status"] == "ok"}, index=data.index
    )
    for name in metrics:
        table[name] = data[name].where(planned)
    grouped = table.groupby(list(by), observed=True, sort=True)
    result = grouped[["tasks", "planned", "clean"]].sum()
    result["planned_rate"] = result["planned"] / result["tasks"]
    result["clean_rate"] = result["clean"] / result["tasks"]
    return result.join(grouped[list(metrics)].median())


def planner_order(data: pd.DataFrame) -> pd.Series:
    """The planner column as a categorical, its categories in the order the planners first
    appear (groups then come in that order)."""
    return data["planner"].astype(pd.CategoricalDtype(list(data["planner"].unique())))


def level_label(value: Any) -> str:
    """A group of :func:`groups` as text: ``0.04``, or a bin's name."""
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def sweep_markdown(
    data: pd.DataFrame,
    parameters: Sequence[str],
    title: str,
    figures: Sequence[str] = (),
    stale: int = 0,
) -> str:
    """The summary: counts, robustness per planner, failures, violations, the medians per
    value of each swept parameter, and links to the ``figures`` (file names).

    ``data`` is a sweep's table with its key metrics (:func:`with_metrics`); ``stale``
    counts the results file's rows left out (not of the sweep's current tasks).
    """
    metrics = shown_metrics(data)
    swept = swept_parameters(data, parameters)
    planner = planner_order(data)
    lines = [f"# {title}", "", *_overview(data, parameters, swept, stale), ""]

    counts = [("all", data)] + [(name, data[planner == name]) for name in planner.cat.categories]
    lines += ["## Counts", ""]
    lines += markdown_table(
        ["planner", "tasks", "ok", "with violations", "failed"],
        [[name, len(part), *_outcome_counts(part["status"])] for name, part in counts],
    )
    lines += ["", "## Robustness per planner", ""]
    lines += [
        "Planned: the planner returned a plan (status not failed); clean: one that breaks "
        "no limit (status ok). Medians over the planned tasks.",
        "",
    ]
    table = robustness(data, [planner], metrics)
    lines += markdown_table(
        ["planner", "tasks", "planned", "clean", "planned %", "clean %"]
        + [f"median {column(m).heading}" for m in metrics],
        [[name, *_robustness_cells(row, metrics)] for name, row in table.iterrows()],
    )

    lines += ["", "## Most common failures", "", *_failures(data)]
    lines += ["", "## Most common violations", "", *_violations(data)]
    for name in swept:
        level = groups(data[name])
        binned = isinstance(level.dtype, pd.CategoricalDtype)
        lines += ["", f"## Medians by {name}", ""]
        lines += [
            (f"In {level.nunique()} quantile bins. " if binned else "")
            + "Over every other parameter; medians over the planned tasks.",
            "",
        ]
        table = robustness(data, [level.rename(name), planner], metrics)
        lines += markdown_table(
            [name, "planner", "tasks", "planned", "clean", "planned %", "clean %"]
            + [f"median {column(m).heading}" for m in metrics],
            [
                [level_label(value), planner_name, *_robustness_cells(row, metrics)]
                for (value, planner_name), row in table.iterrows()
            ],
        )
    if figures:
        lines += ["", "## Figures", ""]
        lines += [f"![{file}]({file})" for file in figures]
    return "\n".join(lines) + "\n"


def _overview(
    data: pd.DataFrame, parameters: Sequence[str], swept: Sequence[str], stale: int
) -> list[str]:
    ok, violations, failed = _outcome_counts(data["status"])
    machine = int((data["failure"] == "machine").sum())
    lines = [
        f"- tasks: {len(data)} ({ok} ok, {violations} with violations, {failed} failed"
        + (f", {machine} of them for the machine's reasons: run the sweep again" if machine else "")
        + f"); planners: {', '.join(data['planner'].unique())}"
    ]
    if stale:
        lines.append(
            f"- {stale} stale rows in {RESULTS_FILE} (of tasks not in this sweep: another "
            "specification or another version of spm_opt) are left out"
        )
    for name in swept:
        values = data[name].dropna()
        if values.nunique() <= MAX_LEVELS:
            shown = ", ".join(level_label(v) for v in sorted(values.unique()))
            lines.append(f"- swept: {name} ({values.nunique()} values: {shown})")
        else:
            lines.append(
                f"- swept: {name} ({values.nunique()} values in "
                f"{values.min():.4g}–{values.max():.4g})"
            )
    if FLAP in parameters:
        lines.append(f"- generated bone flaps: {data[FLAP].nunique()}")
    others = [name for name in parameters if name != FLAP and name not in swept]
    for name in others:
        values = data[name].dropna().astype(str).unique()
        if len(values) == 1:
            lines.append(f"- {name} = {values[0]} in every task")
        else:
            lines.append(f"- {name}: {len(values)} values (not numbers: not tabulated)")
    return lines


def _failures(data: pd.DataFrame) -> list[str]:
    """The failed tasks' commonest errors (their first 80 characters), counted."""
    failed = data[data["status"] == "failed"]
    if failed.empty:
        return ["No task failed."]
    message = failed["error"].str.slice(0, 80)
    counts = message.value_counts()
    lines = markdown_table(
        ["tasks", "planners", "error (first 80 characters)"],
        [
            [count, _planners(failed[message == text]), f"`{text}`" if text else "—"]
            for text, count in counts.head(_FAILURES_SHOWN).items()
        ],
    )
    if len(counts) > _FAILURES_SHOWN:
        lines += ["", f"and {len(counts) - _FAILURES_SHOWN} other messages."]
    return lines


def _violations(data: pd.DataFrame) -> list[str]:
    """The limits the planned tasks break, each with how many tasks break it."""
    status = data["status"]
    violated = data[(status != "ok") & (status != "failed")]
    if violated.empty:
        return ["No planned task breaks a limit."]
    limits = violated.assign(limit=violated["violations"].map(_limits)).explode("limit")
    return markdown_table(
        ["limit", "tasks", "planners"],
        [
            [text, count, _planners(limits[limits["limit"] == text])]
            for text, count in limits["limit"].dropna().value_counts().items()
        ],
    )


def _outcome_counts(status: pd.Series) -> tuple[int, int, int]:
    """(ok, with violations, failed) among the statuses."""
    ok, failed = int((status == "ok").sum()), int((status == "failed").sum())
    return ok, len(status) - ok - failed, failed


def _robustness_cells(row: pd.Series, metrics: Sequence[str]) -> list[str]:
    return [
        f"{row['tasks']:.0f}",
        f"{row['planned']:.0f}",
        f"{row['clean']:.0f}",
        f"{100 * row['planned_rate']:.1f}",
        f"{100 * row['clean_rate']:.1f}",
        *("—" if math.isnan(row[m]) else f"{row[m]:.4g}" for m in metrics),
    ]


def _limits(violations: str) -> list[str]:
    """The limits a row's violations name: ``tool speed: 2.1 mm/s at ...; ...`` →
    ``["tool speed", ...]``."""
    return sorted({found.split(":")[0] for found in violations.split("; ") if found})


def _planners(rows: pd.DataFrame) -> str:
    """``cubic (3), toppra (1)``: how many of the rows each planner has."""
    return ", ".join(f"{name} ({count})" for name, count in rows["planner"].value_counts().items())
