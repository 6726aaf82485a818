"""The figure rules (:mod:`spm_opt.report.figure_rules`): the checker on hand-made figures that
break each rule, and every figure-writing path exercised.

tests/conftest.py checks every figure a test saves. The figures of ``compare``,
``reproduce``, ``sweep`` and the hardware verification are saved by the tests that
:data:`FIGURE_WRITERS` names; those of ``identify`` (whose own tests are slow) and of the
experiments (which their test runs in subprocesses, out of the check's reach) are drawn
here from small data.
"""

from __future__ import annotations

import importlib.util
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import experiment_module
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from test_identify import synthetic_samples, with_efficiency

import spm_opt as so
from spm_opt.identify.report import prediction_figure
from spm_opt.identify.validate import hold_out
from spm_opt.judge.limits import contour_tube
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.report import comparison_figures
from spm_opt.report.figure_rules import ANTERIOR, TOP_VIEW, figure_faults, has_unit, mark_top_view
from spm_opt.report.plots import REST_STEP, friction_figure, moving_grid, to_png
from spm_opt.studies.comparison import run_planner
from spm_opt.studies.hardware_comparisons import CutComparison, RunSamples
from spm_opt.studies.hardware_figures import cut_figure
from spm_opt.studies.sweep import results_figures

ROOT = Path(__file__).resolve().parents[1]
FIGURE_WRITERS = {
    "spm_opt/studies/comparison.py": (
        "test_comparison.py",
        "test_command_writes_the_table_the_summary_and_the_figures",
    ),
    "spm_opt/studies/reproduce.py": (
        "test_reproduce.py",
        "test_reproduce_command_writes_tables_figures_and_report",
    ),
    "spm_opt/studies/sweep/results.py": (
        "test_sweep_results.py",
        "test_drawn_flap_parameters_are_tabulated_and_drawn",
    ),
    "spm_opt/studies/hardware.py": (
        "test_verify_hardware.py",
        "test_every_file_is_written_and_each_figure_is_a_real_png",
    ),
    "spm_opt/report/review_png.py": (
        "test_review.py",
        "test_the_png_is_a_picture_of_sensible_size",
    ),
    "spm_opt/cli/commands.py": (
        "test_figures.py",
        "test_the_identification_figure_is_over_time_with_a_title",
    ),
    "experiments/feed_hold.py": ("test_figures.py", "test_the_feed_hold_figure_keeps_the_rules"),
    "experiments/kinematic_calibration.py": (
        "test_comparison.py",
        "test_every_experiment_script_runs",
    ),
    "experiments/executed_cut.py": (
        "test_figures.py",
        "test_the_executed_cut_experiment_shows_the_cut_too",
    ),
    "experiments/compensated_cut.py": (
        "test_figures.py",
        "test_the_compensated_cut_figures_keep_the_rules",
    ),
}
"""Every file that writes a figure, and the test that saves its figures (checked)."""


def _panel(title: str = "speed", x: str = "time (s)", y: str = "speed (mm/s)") -> Figure:
    """A one-panel figure of a rising line, labelled and titled as given."""
    figure = Figure(figsize=(5, 4), layout="constrained")
    axis = figure.subplots()
    axis.plot([0.0, 1.0, 2.0], [0.0, 1.0, 4.0], label="measured")
    axis.set_title(title)
    axis.set_xlabel(x)
    axis.set_ylabel(y)
    return figure


def _legend_at_data(figure: Figure) -> None:
    """Put a point of data where the figure's first panel's legend lies."""
    axis = figure.axes[0]
    figure.draw_without_rendering()
    centre = axis.get_legend().get_window_extent().corners().mean(axis=0)
    axis.plot(*axis.transData.inverted().transform(centre), "o")


# ------------------------------------------------------------------------- the checker
@pytest.mark.parametrize(
    ("label", "expected"),
    [
        ("speed (mm/s)", True),
        ("torque (N·m)", True),
        ("effort ∫τᵀτ dt (N²·m²·s)", True),
        ("RMS jerk (rad/s³)", True),
        ("duration / lower bound (-)", True),
        ("tasks (%)", True),
        ("violations (count)", True),
        ("joint rate (deg/s)", True),
        ("speed", False),
        ("speed, mm/s", False),
        ("tasks clean (solid)", False),
        ("time (s; slow stretches left out)", False),
    ],
)
def test_a_unit_is_a_unit_in_parentheses(label: str, expected: bool) -> None:
    assert has_unit(label) is expected


def test_a_figure_that_keeps_every_rule_has_no_fault() -> None:
    figure = _panel()
    figure.axes[0].legend(loc="upper left")
    assert figure_faults(figure) == []


def test_an_axis_that_shows_numbers_needs_a_label_with_its_unit() -> None:
    assert figure_faults(_panel(x="time")) == [
        "panel 0 ('speed'): the x axis label 'time' has no unit"
    ]
    assert figure_faults(_panel(y="")) == [
        "panel 0 ('speed'): the y axis shows numbers but has no label"
    ]
    shared = _panel(x="")
    shared.supxlabel("time (s)")  # the figure's label serves the panels without one
    assert figure_faults(shared) == []


def test_names_need_no_unit_but_colour_bars_and_twins_do() -> None:
    bars = Figure()
    axis = bars.subplots()
    axis.bar(["cubic", "toppra"], [1.0, 2.0])
    axis.set_ylabel("violations (count)")
    axis.set_title("by planner")
    assert figure_faults(bars) == []
    heat = Figure(layout="constrained")
    axis = heat.subplots()
    colour_bar = heat.colorbar(axis.imshow(np.eye(3)), ax=axis, label="duration")
    axis.set(title="grid", xlabel="μ (-)", ylabel="mass (kg)")
    assert figure_faults(heat) == ["colour bar of panel 0 ('grid'): label 'duration' has no unit"]
    colour_bar.set_label("duration (s)")
    assert figure_faults(heat) == []
    twin = _panel()
    twin.axes[0].twinx().set_ylabel("torque")
    assert figure_faults(twin) == ["panel 1: the y axis label 'torque' has no unit"]


def test_a_figure_needs_a_title_for_every_panel_or_a_suptitle() -> None:
    assert figure_faults(_panel(title="")) == ["panel 0: no title (and the figure has no suptitle)"]
    figure = Figure()
    for axis in figure.subplots(2, 1, sharex=True):
        axis.plot([0.0, 1.0])
        axis.set_ylabel("angle (deg)")
    figure.axes[1].set_xlabel("time (s)")
    assert len(figure_faults(figure)) == 2
    figure.suptitle("joint angles")
    assert figure_faults(figure) == []


def test_a_legend_must_cover_no_data() -> None:
    covered = _panel()
    covered.axes[0].legend(loc="center")
    _legend_at_data(covered)
    assert figure_faults(covered) == [
        "legend of panel 0 ('speed') covers data of panel 0 ('speed')"
    ]
    crossed = _panel()  # a segment through the legend, no point inside it
    crossed.axes[0].plot([0.0, 2.0], [3.8, 3.8])
    crossed.axes[0].legend(loc="upper left")
    assert len(figure_faults(crossed)) == 1
    bar = Figure()
    axis = bar.subplots()
    axis.bar(["a", "b", "c"], [4.0, 1.0, 1.0], label="tasks")
    axis.set(title="bars", ylabel="tasks (count)")
    axis.legend(loc="upper left")
    assert len(figure_faults(bar)) == 1
    reference = _panel()  # a line across the whole panel is a reference, not data
    reference.axes[0].axhline(3.8, label="limit")
    reference.axes[0].legend(loc="upper left")
    assert figure_faults(reference) == []


def test_a_figure_legend_must_cover_no_panel_and_outside_covers_none() -> None:
    figure = _panel()
    figure.legend(loc="center")
    figure.axes[0].set_ylim(-10.0, 10.0)
    figure.axes[0].plot([0.0, 2.0], [0.0, 0.0])
    assert figure_faults(figure) == ["legend of the figure covers data of panel 0 ('speed')"]
    outside = _panel()
    outside.legend(loc="outside lower center")
    assert figure_faults(outside) == []


def test_a_top_view_needs_the_anterior_marker() -> None:
    by_labels = _panel("cut", "x (mm)", "y (mm)")
    assert figure_faults(by_labels) == [
        "panel 0 ('cut'): a top view without the anterior marker (gid 'anterior')"
    ]
    marked = _panel("cut", "across (mm)", "up (mm)")
    marked.axes[0].set_gid(TOP_VIEW)
    assert len(figure_faults(marked)) == 1
    mark_top_view(marked.axes[0])
    mark_top_view(by_labels.axes[0])
    assert figure_faults(marked) == figure_faults(by_labels) == []
    (arrow,) = [text for text in by_labels.axes[0].texts if text.get_gid() == ANTERIOR]
    assert arrow.xy[0] < arrow.xyann[0]  # it points to −x


def test_a_saved_figure_that_breaks_a_rule_fails_the_test(tmp_path: Path) -> None:
    with pytest.raises(pytest.fail.Exception, match="the x axis label 'time' has no unit"):
        _panel(x="time").savefig(tmp_path / "bad.png")
    assert not (tmp_path / "bad.png").exists()


def test_every_figure_writer_has_a_test_that_saves_its_figures() -> None:
    """A file that calls to_png or savefig is listed in FIGURE_WRITERS with a test that
    exists (spm_opt/report/plots.py defines to_png)."""
    sources = [*ROOT.glob("spm_opt/**/*.py"), *ROOT.glob("experiments/*.py")]
    writers = {
        path.relative_to(ROOT).as_posix()
        for path in sources
        if re.search(r"\bto_png\(|\.savefig\(", path.read_text(encoding="utf-8"))
    }
    assert writers - {"spm_opt/report/plots.py"} == set(FIGURE_WRITERS)
    for module, name in FIGURE_WRITERS.values():
        assert f"def {name}(" in (ROOT / "tests" / module).read_text(encoding="utf-8"), name


# ------------------------------------------------------------- the figures as drawn
@dataclass(frozen=True)
class _Planned:
    planner: str
    trajectory: so.Trajectory
    report: None = None


def test_the_cuts_show_the_contour_on_top_the_anterior_and_each_deviation(
    paper_problem: so.Problem, baseline: so.Trajectory
) -> None:
    figure = comparison_figures.cuts(paper_problem, [_Planned("cubic", baseline)])
    top, off = figure.axes
    (contour,) = [line for line in top.lines if line.get_label() == "planned contour"]
    assert all(
        contour.get_zorder() > line.get_zorder() for line in top.lines if line is not contour
    )
    assert top.get_gid() == TOP_VIEW and off.get_yscale() == "log"
    assert off.get_xlabel() == "place along the planned contour (mm)"
    along = off.lines[0].get_xdata()  # from A1 round the loop back to A1
    assert along[0] == pytest.approx(0.0, abs=0.5)
    assert along[-1] == pytest.approx(paper_problem.contour.length / MM, abs=0.5)
    assert figure_faults(figure) == []


def _horizontal_lines(axis: Axes) -> list[float]:
    """The heights of ``axis``'s horizontal lines (its drawn limits)."""
    return [
        float(line.get_ydata()[0])
        for line in axis.lines
        if len(set(np.asarray(line.get_ydata(), float))) == 1
    ]


def test_the_cuts_draw_both_tubes_at_their_heights_and_name_them(
    paper_problem: so.Problem, baseline: so.Trajectory
) -> None:
    figure = comparison_figures.cuts(paper_problem, [_Planned("cubic", baseline)])
    plan, executed = contour_tube(paper_problem) / MM, contour_tube(paper_problem, True) / MM
    assert plan < executed  # the paper's problem keeps a reserve for execution
    assert _horizontal_lines(figure.axes[1]) == pytest.approx([plan, executed])
    words = [text.get_text() for text in figure.legends[0].get_texts()]
    kept = executed - plan
    assert (
        f"plan's tube {plan:.4g} mm ({executed:.4g} mm less {kept:.4g} mm kept for execution)"
        in words
    )
    assert f"executed cut's tube {executed:.4g} mm" in words


@pytest.fixture(scope="module")
def headline_panels(paper_problem: so.Problem) -> dict[str, Axes]:
    """The headline figure of cubic (5 violations) and toppra (none), panels by the
    first line of their titles."""
    outcomes = [run_planner(paper_problem, name) for name in ("cubic", "toppra")]
    figure = comparison_figures.headline(paper_problem, outcomes)
    assert figure_faults(figure) == []
    return {axis.get_title().splitlines()[0]: axis for axis in figure.axes}


def test_the_headline_bars_start_at_zero_or_say_their_axis_is_logarithmic(
    headline_panels: dict[str, Axes],
) -> None:
    assert len(headline_panels) == 6
    for title, axis in headline_panels.items():
        if axis.get_yscale() == "log":
            assert "log scale" in axis.get_ylabel(), title
        else:
            assert axis.get_ylim()[0] == 0.0, title
    assert headline_panels["duration / lower bound"].get_yscale() == "linear"


def test_every_headline_bar_is_labelled_with_its_value_a_zero_count_too(
    headline_panels: dict[str, Axes],
) -> None:
    for title, axis in headline_panels.items():
        labels = [text.get_text() for text in axis.texts]
        assert len(labels) == 2 and all(labels), title
    assert [text.get_text() for text in headline_panels["violations"].texts] == ["5", "0"]


def test_each_headline_panel_draws_its_limit_or_says_it_has_none(
    paper_problem: so.Problem, headline_panels: dict[str, Axes]
) -> None:
    tubes = [contour_tube(paper_problem) / MM, contour_tube(paper_problem, True) / MM]
    speed = paper_problem.limits.max_tool_speed / MM  # type: ignore[operator]
    drawn = {
        "duration / lower bound": [1.0],
        "max contour deviation (mm)": tubes,
        "max tool speed (mm/s)": [speed],
    }
    for title, axis in headline_panels.items():
        assert _horizontal_lines(axis) == pytest.approx(drawn.get(title, [])), title
        if title not in drawn:
            assert "no limit" in axis.get_title() or "0" in axis.get_title(), title
    deviation = headline_panels["max contour deviation (mm)"].get_title()
    assert f"plan's tube {tubes[0]:.4g} mm" in deviation
    assert f"executed cut's tube {tubes[1]:.4g} mm" in deviation


def test_a_problem_without_a_tube_or_a_tool_speed_limit_says_so_in_its_panels(
    hardware_problem: so.Problem,
) -> None:
    """The hardware run cuts nothing: no contour tolerance, no tool speed limit."""
    assert hardware_problem.limits.contour_tolerance is None
    assert hardware_problem.limits.max_tool_speed is None
    figure = comparison_figures.headline(hardware_problem, [run_planner(hardware_problem, "cubic")])
    assert figure_faults(figure) == []
    panels = {axis.get_title().splitlines()[0]: axis for axis in figure.axes}
    for title, words in (
        ("max contour deviation (mm)", "no tube"),
        ("max tool speed (mm/s)", "no limit"),
    ):
        assert _horizontal_lines(panels[title]) == []
        assert words in panels[title].get_title()


@pytest.mark.parametrize("planner", ["cubic", "ocp-min-jerk"])
def test_the_torques_run_to_the_plans_ends_without_a_drop_to_rest(
    paper_problem: so.Problem, planner: str
) -> None:
    """At rest the friction has no direction: the model's torque at the plan's first or
    last instant is far from the torque that starts or stops it (cubic: 0 against
    0.028 N·m; ocp-min-jerk's last piece is 1e-7 s long and its rates' signs there are a
    rounding residue's), and the figure draws the latter."""
    trajectory = so.plan(paper_problem, planner)
    figure = comparison_figures.torques(paper_problem, [_Planned(planner, trajectory)])
    ends = np.array([trajectory.start_time, trajectory.start_time + trajectory.duration])
    state = (trajectory.position(ends), trajectory.velocity(ends), trajectory.acceleration(ends))
    at_rest = dynamics.actuator_torque(paper_problem.robot, *state)  # (2 ends, 2 joints)
    inside = REST_STEP / comparison_figures.RATE_HZ
    drawn = []
    for axis in figure.axes[:2]:
        (line,) = axis.lines
        t, torque = np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
        assert abs(torque[-1] - torque[-2]) < 2e-3 and abs(torque[0] - torque[1]) < 2e-3
        assert t[[0, -1]] == pytest.approx(ends + [inside, -inside], abs=1e-12)
        drawn.append(torque[[0, -1]])
    assert np.abs(at_rest - np.transpose(drawn)).max() > 0.02  # the drop the ends leave out


def test_the_moving_grid_is_the_plain_grid_with_its_ends_inside(baseline: so.Trajectory) -> None:
    plain, moving = baseline.time_grid(200.0), moving_grid(baseline, 200.0)
    np.testing.assert_array_equal(moving[1:-1], plain[1:-1])
    assert moving[0] - plain[0] == pytest.approx(REST_STEP / 200.0)
    assert plain[-1] - moving[-1] == pytest.approx(REST_STEP / 200.0)


def test_the_friction_figure_says_why_it_shows_two_coefficients() -> None:
    t = np.linspace(0.0, 1.0, 5)
    figure = friction_figure(t, np.ones((5, 3)), np.ones((5, 3)), np.ones((5, 2)), 0.24)
    words = figure.get_suptitle() + " ".join(axis.get_title() for axis in figure.axes)
    assert "μ = 1" in words and "proportional to μ" in words and "μ = 0.24" in words
    assert figure_faults(figure) == []


def test_a_heat_map_of_one_value_says_so_and_shows_that_value_alone() -> None:
    cells = pd.DataFrame(
        {
            "x": [0, 1, 0, 1],
            "y": [0, 0, 1, 0],
            "planner": ["a", "a", "a", "b"],
            "planned": [1, 1, 1, 1],
            "clean": [1, 1, 1, 1],
            "median": [37.9, 37.9, 37.9, 40.0],
        }
    )
    figure = results_figures.heatmap(
        cells,
        ("robot.friction.mu", "robot.payload.mass_kg"),
        "a",
        "duration_s",
        "Grid",
        (["0.04", "0.24"], ["0", "0.5"]),
    )
    axis, bar = figure.axes
    assert "constant: every planned cell 37.9" in axis.get_title()
    assert list(bar.get_yticks()) == [37.9]
    assert axis.get_xlabel() == "robot.friction.mu (-)"
    assert axis.get_ylabel() == "robot.payload.mass_kg (kg)"
    assert figure_faults(figure) == []


def test_histograms_of_values_over_decades_are_log_spaced() -> None:
    points = pd.DataFrame(
        {
            "planner": ["a"] * 20 + ["b"] * 20,
            "max_contour_deviation_mm": np.r_[
                np.geomspace(1e-10, 1e-8, 20), np.linspace(1, 10, 20)
            ],
            "duration_s": np.linspace(30.0, 40.0, 40),
        }
    )
    figure = results_figures.histograms(points, ["a", "b"], "Flaps")
    deviation, duration = figure.axes
    assert deviation.get_xscale() == "log" and duration.get_xscale() == "linear"
    edges = np.unique(deviation.patches[0].get_xy()[:, 0])
    assert np.allclose(np.diff(np.log(edges)), np.log(edges[1] / edges[0]))  # log-spaced
    assert figure_faults(figure) == []


def test_one_flap_per_value_is_drawn_as_outcomes_not_rates() -> None:
    rates = {
        "flap_size_mm": pd.DataFrame(
            {
                "group": ["20", "20", "30", "30", "40", "40"],
                "planner": ["a", "b"] * 3,
                "planned_rate": [1.0, 1.0, 1.0, 0.0, 1.0, 1.0],
                "clean_rate": [1.0, 0.0, 1.0, 0.0, 1.0, 1.0],
            }
        )
    }
    figure = results_figures.flap_rates(rates, ["a", "b"], 3, "Small")
    (axis,) = figure.axes
    assert "one flap per value" in axis.get_title()
    assert [label.get_text() for label in axis.get_yticklabels()] == ["a", "b"]
    outcomes = {label: 0 for label in ("clean", "breaks a limit", "failed")}
    for line in axis.lines:
        outcomes[line.get_label()] += len(line.get_xdata())
    assert outcomes == {"clean": 4, "breaks a limit": 1, "failed": 1}
    assert figure_faults(figure) == []


def test_the_executed_cut_figure_shows_the_distance_along_the_plans_cut() -> None:
    """A 10 s arc of plan, executed 0.02 mm off: the distance along runs to the arc's length."""
    t = np.linspace(0.0, 10.0, 501)
    q = np.column_stack([np.linspace(0.0, 20.0, 501), np.zeros(501)]) * DEG
    fine = np.column_stack([np.linspace(0.0, 20.0, 20001), np.zeros(20001)]) * DEG
    planned = 0.07 * kinematics.forward_kinematics(fine, 1.0)
    executed = (0.07 + 0.02 * MM) * kinematics.forward_kinematics(q, 1.0)
    ones, zeros = np.ones(501), np.zeros((501, 2))
    samples = RunSamples(0.0, t, ones, ones, q, zeros, zeros, q, zeros)
    cut = CutComparison(planned, executed, np.full(501, 0.02 * MM))
    figure = cut_figure(samples, cut, [])
    top, off = figure.axes
    along = off.lines[0].get_xdata()
    assert along[-1] == pytest.approx(0.07 * np.radians(20.0) / MM, rel=1e-3)
    assert np.all(np.diff(along) >= 0.0)
    np.testing.assert_allclose(off.lines[0].get_ydata(), 0.02)
    assert top.get_gid() == TOP_VIEW
    assert figure_faults(figure) == []


def test_the_identification_figure_is_over_time_with_a_title(tmp_path: Path) -> None:
    robot = so.load_problem(ROOT / "problems" / "craniotomy_hardware.toml").robot
    fitted, held = hold_out(synthetic_samples(robot, seed=0, duration_s=20.0), 0.2)
    assert held is not None
    figure = prediction_figure(robot, with_efficiency(robot, 0.9), [(fitted, False), (held, True)])
    assert figure.get_suptitle().startswith("Torque prediction")
    assert figure.axes[1].get_xlabel() == "time (s)"
    end = np.nanmax(figure.axes[0].lines[0].get_xdata())
    assert 19.0 < end <= 20.0  # seconds of the 20 s log, not samples
    (shaded,) = figure.axes[0].patches  # the held-out last 4 s
    assert shaded.get_x() == pytest.approx(16.0, abs=0.2)
    (tmp_path / "identified.png").write_bytes(to_png(figure))


def test_the_feed_hold_figure_keeps_the_rules(tmp_path: Path) -> None:
    rows = [
        {
            "hold_s": at,
            "goal_stop_mm": 0.1 + 0.01 * at,
            "tool_stop_mm": 0.1 + 0.011 * at,
            "feed_to_zero_s": 0.1,
            "true_rest_s": 0.08,
            "rest_confirmed_s": 0.3 + 0.01 * at,
        }
        for at in (1.0, 3.0, 5.0)
    ]
    figure = experiment_module("feed_hold").figure(rows)
    assert "feed hold" in figure.get_suptitle()
    (tmp_path / "feed_hold.png").write_bytes(to_png(figure))


def test_the_executed_cut_experiment_shows_the_cut_too(tmp_path: Path) -> None:
    module = experiment_module("executed_cut")
    rows = [
        module.Row(
            problem=problem,
            planner=planner,
            plant="prototype_plant",
            tracking=tracking,
            completed=True,
            outcome="completed",
            planned_deviation_mm=0.0 if planner == "toppra" else 0.07,
            true_tracking_error_deg=0.1 if tracking == "lead" else 0.3,
            measured_tracking_error_deg=0.1,
            true_deviation_mm=0.09,
            predicted_deviation_mm=0.085,
            tube_mm=tube,
            violations=0,
            true_broken_limits=["theta2 jerk"],
            predicted_broken_limits=["theta2 jerk"],
            duration_s=38.2,
            pace_at_breakaways=1.0,
            worst_share_of_limit={"speed": 0.3, "acceleration": 1.2, "jerk": 2.5},
            predicted_share_of_limit={"speed": 0.3, "acceleration": 1.1, "jerk": 2.3},
        )
        for problem, tube in (("hardware", None), ("bone_flap", 0.1))
        for planner in ("toppra", "ocp-min-time")
        for tracking in ("none", "lead")
    ]
    module.figure(rows, tmp_path / "executed_cut.png")  # checked as it is saved
    assert (tmp_path / "executed_cut.png").stat().st_size > 10_000


def test_the_frames_figure_of_the_docs_keeps_the_rules() -> None:
    spec = importlib.util.spec_from_file_location(
        "frames_figure", ROOT / "docs" / "scripts" / "frames_figure.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    problem = so.load_problem(ROOT / "problems" / "craniotomy_bone_flap.toml")
    assert figure_faults(module.frames_figure(problem)) == []


def _shares(scale: float) -> dict[str, float]:
    """A run's joint limit shares, ``scale`` of a spread of them."""
    base = {"speed": 0.3, "acceleration": 0.6, "jerk": 0.8}
    return {
        f"theta{joint} {figure}": scale * share * (1.0 + 0.1 * joint)
        for figure, share in base.items()
        for joint in (1, 2)
    }


def _run(true_mm: float, scale: float) -> dict:
    """A true run: its cut (mm) and its joint limit shares."""
    return {"true_mm": true_mm, "limit_shares": _shares(scale)}


def test_the_compensated_cut_figures_keep_the_rules(tmp_path: Path) -> None:
    rows = [
        {
            "plant": plant,
            "flap": flap,
            "planner": planner,
            "tube_mm": 0.12,
            "predicted_lead_mm": 0.05 + 0.01 * plant,
            "predicted_lead_shares": _shares(1.0 + 0.05 * plant),
            "lead": _run(0.052 + 0.01 * plant, 1.02 + 0.05 * plant),
            "predicted_compensated_mm": 0.03 + 0.01 * plant,
            "predicted_compensated_shares": _shares(1.1),
            "compensated": _run(0.031 + 0.01 * plant, 1.12),
            "slowed": {
                "predicted_mm": 0.02 + 0.01 * plant,
                "predicted_shares": _shares(0.8),
                "run": _run(0.021, 0.82),
                "lead_predicted_mm": 0.025,
                "lead_predicted_shares": _shares(0.7),
                "lead_run": _run(0.026, 0.71) if plant == 1 else None,
            }
            if planner == "toppra"
            else None,
            "highest_feed": {
                "predicted_mm": 0.11,
                "predicted_shares": _shares(0.5),
                "run": _run(0.112, 0.5),
            }
            if plant == 2 and planner == "ocp-min-time"
            else None,
        }
        for plant in (1, 2)
        for flap in ("craniotomy_bone_flap", "craniotomy_five_landmarks")
        for planner in ("toppra", "ocp-min-time")
    ]
    study = experiment_module("compensated_cut")
    for name, figure in (("cut", study.figure(rows)), ("limits", study.limits_figure(rows))):
        figure.savefig(tmp_path / f"{name}.png")  # checked as it is saved
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000
