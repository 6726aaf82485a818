"""A sweep's results: reading results.jsonl and writing the report, on synthetic rows."""

import ast
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from spm_opt.base.errors import InputError
from spm_opt.report.columns import COLUMNS
from spm_opt.studies.sweep import results_figures
from spm_opt.studies.sweep.results import (
    load_sweep,
    sweep_figures,
    sweep_markdown,
    with_metrics,
    write_sweep_report,
)

MU = [0.0025, 0.04, 0.24]
MASS = [0.0, 0.25, 0.5]
PNG = b"\x89PNG\r\n\x1a\n"


def _row(key: str, sweep: str, planner: str, parameters: dict, status: str, **metrics) -> dict:
    """A row as the runner writes it: every comparison column, null where a task failed."""
    row = {"key": key, "sweep": sweep, "planner": planner, "parameters": parameters}
    row.update(dict.fromkeys(COLUMNS))
    row.update(planner=planner, status=status, violations="", error="")
    if status == "failed":
        row["error"] = metrics.pop("error")
    else:
        duration = metrics.pop("duration_s")
        row.update(
            solve_time_s=0.01,
            wall_time_s=0.5,
            duration_s=duration,
            duration_over_lower_bound=duration / 30.0,
            peak_torque_1_nm=0.1 * duration,
            peak_torque_2_nm=0.2 * duration,
            effort_n2m2s=duration / 100,
            max_contour_deviation_mm=1e-4,
            max_tool_speed_mm_s=2.0,
        )
        if status != "ok":
            row["violations"] = "tool speed: 2.1 mm/s at t = 3.000 s (allowed 2 mm/s)"
    row.update(metrics, worker="host:1", finished_at="2026-11-23T16:20:00Z")
    return row


def _write(directory: Path, rows: list[dict], tail: str = "") -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    text = "".join(json.dumps(row) + "\n" for row in rows) + tail
    (directory / "results.jsonl").write_text(text, encoding="utf-8")
    return directory


def _grid_rows() -> list[dict]:
    """3 × 3 grid × 2 planners. cubic: always planned, duration 40 + 100 μ + 10 m, clean
    except at μ = 0.24 (violations); toppra: fails at m = 0.5, else duration 30 + 100 μ.
    Only duration and effort are known (the other key metrics are left out: fewer figures)."""
    rows = []
    unknown = dict.fromkeys(
        ["duration_over_lower_bound", "max_contour_deviation_mm", "max_tool_speed_mm_s"]
        + ["peak_torque_1_nm", "peak_torque_2_nm", "wall_time_s"]
    )
    for i, mu in enumerate(MU):
        for j, mass in enumerate(MASS):
            parameters = {"robot.friction.mu": mu, "robot.payload.mass_kg": mass}
            status = "1 violation(s)" if mu == 0.24 else "ok"
            duration = 40 + 100 * mu + 10 * mass
            rows.append(_row(f"c{i}{j}", "fp", "cubic", parameters, status, duration_s=duration))
            if mass == 0.5:
                error = f"PlanningError: infeasible at mu={mu}"
                rows.append(_row(f"t{i}{j}", "fp", "toppra", parameters, "failed", error=error))
            else:
                duration = 30 + 100 * mu
                rows.append(_row(f"t{i}{j}", "fp", "toppra", parameters, "ok", duration_s=duration))
    return [{**row, **unknown} for row in rows]


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write(tmp_path_factory.mktemp("grid"), _grid_rows())


@pytest.fixture(scope="module")
def grid_report(grid: Path) -> list[Path]:
    """The grid's report, written once for the tests that read it."""
    return write_sweep_report(grid, title="Friction and payload")


@pytest.fixture(scope="module")
def flaps(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 flaps × 3 planners; "ocp" fails on flaps 0-3, "toppra" breaks a limit on 8 and 9."""
    rows = []
    for flap in range(10):
        parameters = {"flap": flap, "flap_size_mm": 20.0 + 3.0 * flap}
        rows.append(_row(f"c{flap}", "flaps", "cubic", parameters, "ok", duration_s=40.0 + flap))
        status = "1 violation(s)" if flap >= 8 else "ok"
        rows.append(_row(f"t{flap}", "flaps", "toppra", parameters, status, duration_s=30.0 + flap))
        if flap < 4:
            rows.append(_row(f"o{flap}", "flaps", "ocp", parameters, "failed", error="Timeout"))
        else:
            rows.append(_row(f"o{flap}", "flaps", "ocp", parameters, "ok", duration_s=25.0 + flap))
    return _write(tmp_path_factory.mktemp("flaps"), rows)


@pytest.fixture(scope="module")
def varied_flaps(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """30 flaps × 2 planners, with drawn landmark counts (4, 5, 6 in turn), tolerances and
    tool-speed limits: "cubic" always clean; "ocp" fails on every 6-landmark flap."""
    rows = []
    for flap in range(30):
        landmarks = 4 + flap % 3
        parameters = {
            "flap": flap,
            "flap_size_mm": 20.0 + flap,
            "flap_landmarks": landmarks,
            "limits.contour_tolerance_mm": 0.05 * 4 ** (flap / 29),
            "limits.max_tool_speed_mm_s": 2.0 + flap / 15,
        }
        rows.append(_row(f"c{flap}", "varied", "cubic", parameters, "ok", duration_s=40.0))
        if landmarks == 6:
            rows.append(_row(f"o{flap}", "varied", "ocp", parameters, "failed", error="Timeout"))
        else:
            rows.append(_row(f"o{flap}", "varied", "ocp", parameters, "ok", duration_s=30.0))
    return _write(tmp_path_factory.mktemp("varied"), rows)


def _section(summary: str, heading: str) -> list[list[str]]:
    """The cells of the table under a markdown heading."""
    part = summary.split(f"## {heading}\n", 1)[1].split("\n## ", 1)[0]
    lines = [line for line in part.splitlines() if line.startswith("| ")][1:]
    return [[cell.strip() for cell in line.strip("| ").split(" | ")] for line in lines]


def test_load_sweep_flattens_parameters_and_keeps_every_field(grid: Path) -> None:
    frame = load_sweep(grid)
    assert frame.shape[0] == 18
    assert list(frame.columns[:5]) == [
        "key",
        "sweep",
        "planner",
        "robot.friction.mu",
        "robot.payload.mass_kg",
    ]
    assert set(COLUMNS) <= set(frame.columns)
    assert list(frame.columns[-2:]) == ["worker", "finished_at"]
    assert frame.attrs["parameters"] == ["robot.friction.mu", "robot.payload.mass_kg"]
    row = frame.set_index("key").loc["c21"]
    assert row["robot.friction.mu"] == 0.24 and row["robot.payload.mass_kg"] == 0.25
    assert row["duration_s"] == pytest.approx(40 + 24 + 2.5)
    assert row["status"] == "1 violation(s)"
    failed = frame.set_index("key").loc["t02"]
    assert failed["status"] == "failed" and math.isnan(failed["duration_s"])
    assert failed["error"] == "PlanningError: infeasible at mu=0.0025"
    assert frame["duration_s"].dtype == np.float64
    assert frame["peak_torque_1_nm"].dtype == np.float64


def test_torn_last_line_is_ignored_and_the_last_row_of_a_key_wins(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    rows = _grid_rows()
    rows.append({**rows[0], "status": "failed", "duration_s": None, "error": "rerun"})
    directory = _write(tmp_path / "torn", rows, tail='{"key": "c99", "sweep": "fp", "plan')
    frame = load_sweep(directory)
    assert len(frame) == 18 and frame["key"].is_unique and "c99" not in set(frame["key"])
    assert "line 20: torn last line ignored" in caplog.text
    rerun = frame.set_index("key").loc["c00"]
    assert rerun["status"] == "failed" and rerun["error"] == "rerun"


def test_only_text_after_the_last_newline_is_torn(tmp_path: Path) -> None:
    rows = _grid_rows()
    complete = json.dumps(rows[1])  # a whole row without its newline is torn too
    assert list(load_sweep(_write(tmp_path, rows[:1], tail=complete))["key"]) == ["c00"]
    with pytest.raises(InputError, match="line 2: not valid JSON"):
        load_sweep(_write(tmp_path, rows[:1], tail='{"key": "c0\n'))


def test_an_empty_sweep_is_an_empty_table(tmp_path: Path) -> None:
    frame = load_sweep(_write(tmp_path / "empty", []))
    assert frame.empty and "duration_s" in frame.columns
    with pytest.raises(InputError, match="no finished task"):
        write_sweep_report(tmp_path / "empty")


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ('{"key": "x", "planner"', "line 2: not valid JSON"),
        ("[1, 2]", "line 2: expected a JSON object"),
        ('{"planner": "cubic", "status": "ok"}', "line 2: 'key' must be a string"),
        ('{"key": "x", "planner": "cubic", "status": "ok", "parameters": 3}', "line 2: 'param"),
        ('{"key": "x", "planner": "cubic", "status": "ok", "duration_s": "long"}', "line 2: 'dur"),
        ('{"key": "x", "planner": "c", "status": "ok", "parameters": {"status": 1}}', "line 2: p"),
    ],
)
def test_a_bad_line_names_its_number(tmp_path: Path, line: str, match: str) -> None:
    rows = _grid_rows()
    text = json.dumps(rows[0]) + "\n" + line + "\n" + json.dumps(rows[1]) + "\n"
    (tmp_path / "results.jsonl").write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=match):
        load_sweep(tmp_path)


def test_missing_directory_or_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such sweep directory"):
        load_sweep(tmp_path / "nowhere")
    with pytest.raises(InputError, match="results.jsonl: no such file"):
        load_sweep(tmp_path)


def test_grid_report(grid: Path, grid_report: list[Path]) -> None:
    paths = grid_report
    names = {path.name for path in paths}
    assert paths == sorted(paths) and all(path.parent == grid for path in paths)
    heatmaps = {
        f"heatmap_{p}_{m}.png" for p in ("cubic", "toppra") for m in ("duration_s", "effort_n2m2s")
    }
    assert names == {
        "results.parquet",
        "results.csv",
        "summary.md",
        "metrics_vs_robot_friction_mu.png",
        "metrics_vs_robot_payload_mass_kg.png",
        *heatmaps,
    }
    for path in paths:
        if path.suffix == ".png":
            assert path.read_bytes().startswith(PNG)
    assert not list(grid.glob(".*.tmp"))

    summary = (grid / "summary.md").read_text(encoding="utf-8")
    assert summary.startswith("# Friction and payload\n")
    assert _section(summary, "Counts") == [
        ["all", "18", "12", "3", "3"],
        ["cubic", "9", "6", "3", "0"],
        ["toppra", "9", "6", "0", "3"],
    ]
    assert (
        "| planner | tasks | planned | clean | planned % | clean % | median duration s | "
        "median ∫τᵀτ N²m²s |" in summary
    )  # the key metrics no task has are left out
    cubic, toppra = _section(summary, "Robustness per planner")
    # planner, tasks, planned, clean, planned %, clean %, median duration s, ...
    assert cubic[:7] == ["cubic", "9", "9", "6", "100.0", f"{100 * 6 / 9:.1f}", "46.5"]
    assert toppra[:7] == ["toppra", "9", "6", "6", f"{100 * 6 / 9:.1f}", f"{100 * 6 / 9:.1f}", "34"]
    failures = _section(summary, "Most common failures")
    assert len(failures) == 3 and all(row[:2] == ["1", "toppra (1)"] for row in failures)
    assert _section(summary, "Most common violations") == [["tool speed", "3", "cubic (3)"]]
    by_mu = _section(summary, "Medians by robot.friction.mu")
    assert [row[:2] for row in by_mu] == [
        [mu, planner] for mu in ("0.0025", "0.04", "0.24") for planner in ("cubic", "toppra")
    ]
    # at μ = 0.24 toppra plans 2 of 3 (m = 0.5 fails), durations 30 + 24 both times
    assert by_mu[-1][2:8] == ["3", "2", "2", f"{100 * 2 / 3:.1f}", f"{100 * 2 / 3:.1f}", "54"]
    # cubic at m = 0.5: durations 45 + 100 μ, median at μ = 0.04
    assert _section(summary, "Medians by robot.payload.mass_kg")[4][:8] == [
        "0.5",
        "cubic",
        "3",
        "3",
        "2",
        "100.0",
        f"{100 * 2 / 3:.1f}",
        "49",
    ]
    assert "![metrics_vs_robot_friction_mu.png](metrics_vs_robot_friction_mu.png)" in summary


def test_parquet_and_csv_round_trip(grid: Path, grid_report: list[Path]) -> None:
    frame = load_sweep(grid)
    pd.testing.assert_frame_equal(pd.read_parquet(grid / "results.parquet"), frame)
    csv = pd.read_csv(grid / "results.csv", keep_default_na=False, na_values=[""])
    assert list(csv.columns) == list(frame.columns)
    np.testing.assert_array_equal(csv["duration_s"], frame["duration_s"])


def test_flap_report(flaps: Path) -> None:
    names = {path.name for path in write_sweep_report(flaps)}
    assert {
        "flap_robustness.png",
        "flap_histograms.png",
        "flap_robustness_by_parameter.png",
        "metrics_vs_flap_size_mm.png",
    } <= names
    assert not any(name.startswith("heatmap_") or name == "metrics_vs_flap.png" for name in names)
    summary = (flaps / "summary.md").read_text(encoding="utf-8")
    assert summary.startswith("# Sweep flaps\n")
    assert "- generated bone flaps: 10" in summary
    robustness = {row[0]: row[1:7] for row in _section(summary, "Robustness per planner")}
    assert robustness == {  # tasks, planned, clean, %, %, median duration (the planned ones)
        "cubic": ["10", "10", "10", "100.0", "100.0", "44.5"],
        "toppra": ["10", "10", "8", "100.0", "80.0", "34.5"],
        "ocp": ["10", "6", "6", "60.0", "60.0", "31.5"],
    }
    assert summary.count("| median ") == 7 * 2  # every key metric, in two tables
    assert _section(summary, "Most common failures") == [["4", "ocp (4)", "`Timeout`"]]
    # 10 sizes, not more than MAX_LEVELS: a row per size and planner
    assert len(_section(summary, "Medians by flap_size_mm")) == 30


def test_drawn_flap_parameters_are_tabulated_and_drawn(varied_flaps: Path) -> None:
    names = {path.name for path in write_sweep_report(varied_flaps)}
    assert {
        "flap_robustness.png",
        "flap_robustness_by_parameter.png",
        "metrics_vs_flap_landmarks.png",
        "metrics_vs_limits_contour_tolerance_mm.png",
        "metrics_vs_limits_max_tool_speed_mm_s.png",
    } <= names
    summary = (varied_flaps / "summary.md").read_text(encoding="utf-8")
    assert "- swept: flap_landmarks (3 values: 4, 5, 6)" in summary
    by_count = _section(summary, "Medians by flap_landmarks")
    # landmarks, planner, tasks, planned, clean, planned %, clean %
    assert [row[:7] for row in by_count] == [
        ["4", "cubic", "10", "10", "10", "100.0", "100.0"],
        ["4", "ocp", "10", "10", "10", "100.0", "100.0"],
        ["5", "cubic", "10", "10", "10", "100.0", "100.0"],
        ["5", "ocp", "10", "10", "10", "100.0", "100.0"],
        ["6", "cubic", "10", "10", "10", "100.0", "100.0"],
        ["6", "ocp", "10", "0", "0", "0.0", "0.0"],
    ]
    by_tolerance = _section(summary, "Medians by limits.contour_tolerance_mm")
    assert len(by_tolerance) == 5 * 2 and by_tolerance[0][0].startswith("0.05–")


def test_the_rates_figure_draws_the_rates_it_is_given() -> None:
    rates = {
        "flap_landmarks": pd.DataFrame(
            {
                "group": ["4", "4", "6", "6"],
                "planner": ["a", "b", "a", "b"],
                "planned_rate": [1.0, 0.5, 1.0, 0.0],
                "clean_rate": [0.9, 0.5, 0.8, 0.0],
            }
        ),
        "limits.max_tool_speed_mm_s": pd.DataFrame(
            {
                "group": ["2–3", "3–4"],
                "planner": ["a", "a"],
                "planned_rate": [1.0, 1.0],
                "clean_rate": [0.25, 0.75],
            }
        ),
    }
    figure = results_figures.flap_rates(rates, ["a", "b"], 7, "Varied")
    first, second = figure.axes
    assert [t.get_text() for t in first.get_xticklabels()] == ["4", "6"]
    assert first.get_xlabel() == "flap_landmarks (count)"
    assert second.get_xlabel().startswith("limits.")
    clean_b = [line for line in first.lines if line.get_label() == "b"][0]
    np.testing.assert_array_equal(clean_b.get_ydata(), [50.0, 0.0])
    assert len(second.lines) == 2  # planner b has no group there: nothing drawn
    assert "7 generated bone flaps" in figure.texts[0].get_text()


def test_many_values_are_binned(tmp_path: Path) -> None:
    rows = [
        _row(
            f"k{n}",
            "random",
            "cubic",
            {"limits.max_tool_speed_mm_s": 2.0 + n / 10},
            "ok",
            duration_s=40.0 - n / 10,
        )
        for n in range(40)
    ]
    data = with_metrics(load_sweep(_write(tmp_path, rows)))
    summary = sweep_markdown(data, data.attrs["parameters"], "Random")
    table = _section(summary, "Medians by limits.max_tool_speed_mm_s")
    assert "In 5 quantile bins." in summary
    assert [row[:3] for row in table] == [
        ["2–2.7", "cubic", "8"],
        ["2.8–3.5", "cubic", "8"],
        ["3.6–4.3", "cubic", "8"],
        ["4.4–5.1", "cubic", "8"],
        ["5.2–5.9", "cubic", "8"],
    ]
    assert table[0][7] == f"{40 - 0.35:.4g}"  # median duration of the first 8
    names = [name for name, _ in sweep_figures(data, data.attrs["parameters"], "Random")]
    assert names == ["metrics_vs_limits_max_tool_speed_mm_s.png"]


def test_failures_say_whose_they_are_and_stale_rows_are_counted(tmp_path: Path) -> None:
    rows = _grid_rows()
    rows[1]["failure"] = "machine"  # t00 failed: a worker killed
    rows[3]["failure"] = "result"  # t01 failed: cannot be planned
    directory = _write(tmp_path, rows)
    frame = load_sweep(directory)
    failure = frame.set_index("key")["failure"]
    assert (failure["t00"], failure["t01"], failure["c00"]) == ("machine", "result", "")
    summary = sweep_markdown(with_metrics(frame), frame.attrs["parameters"], "Grid", stale=4)
    assert "3 failed, 1 of them for the machine's reasons: run the sweep again)" in summary
    assert "- 4 stale rows in results.jsonl" in summary
    with pytest.raises(InputError, match=r"no finished task to report on \(18 stale rows\)$"):
        write_sweep_report(directory, keys=["not-a-key"])


def test_figures_draw_the_data_they_are_given() -> None:
    """A heat map draws its cells as given: a value, "*" where a task breaks a limit,
    "failed" where none was planned; the other planner's cells only set the colour scale."""
    cells = pd.DataFrame(
        {
            "x": [0, 1, 0, 1],
            "y": [0, 0, 1, 1],
            "planner": ["a", "a", "a", "b"],
            "planned": [2, 2, 0, 1],
            "clean": [2, 1, 0, 1],
            "median": [1.5, 2.25, np.nan, 9.0],
        }
    )
    figure = results_figures.heatmap(
        cells, ("mu", "mass"), "a", "duration_s", "Grid", (["0.1", "0.2"], ["0", "1"])
    )
    axis = figure.axes[0]
    assert sorted(text.get_text() for text in axis.texts) == ["1.5", "2.25*", "failed"]
    assert axis.images[0].get_clim() == (1.5, 9.0)
    assert axis.get_xlabel() == "mu (-)" and "duration (s)" in axis.get_title()


def test_the_figures_module_imports_no_module_that_computes() -> None:
    """The figures take data: their module imports plotting and the report's words only
    (never the results module, which imports it)."""
    tree = ast.parse(Path(results_figures.__file__).read_text(encoding="utf-8"))
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    allowed = {"__future__", "math", "collections.abc", "typing", "numpy", "pandas"}
    allowed |= {"matplotlib", "matplotlib.axes", "matplotlib.figure", "spm_opt.report.columns"}
    allowed |= {"spm_opt.report.planner_style"}  # styles and labels, from the report's words
    assert imported <= allowed, imported - allowed
