"""Sweep specifications: expansion into tasks, keys, and one-line errors for bad specs."""

from __future__ import annotations

import dataclasses
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_bad_inputs import assert_one_error, run_cli

import spm_opt as so
from spm_opt.base.fields import Table
from spm_opt.studies.sweep.flaps import DURATION_SPEED_FRACTION
from spm_opt.studies.sweep.spec import _grid, load_sweep_spec
from spm_opt.studies.sweep.task import ProblemFiles, _anchor_plan, code_identity, run_task

ROOT = Path(__file__).resolve().parents[1]
SWEEPS = ROOT / "problems" / "sweeps"
PROBLEM = (ROOT / "problems" / "craniotomy_bone_flap.toml").as_posix()

GOOD = f'''
name = "small"
problem = "{PROBLEM}"
planners = ["cubic", "ruckig"]

[grid]
"robot.friction.mu" = [0.04, 0.24]
"limits.max_tool_speed_mm_s" = [2.0, 3.0, 4.0]

[random]
samples = 2
seed = 5
[random.ranges]
"robot.payload.mass_kg" = [0.0, 0.5]
'''


FLAPS = f'''
name = "varied"
problem = "{PROBLEM}"
planners = ["cubic"]

[flaps]
count = 12
seed = 3
size_mm = [20.0, 50.0]
landmarks = [4, 6]
contour_tolerance_mm = [0.05, 0.2]
max_tool_speed_mm_s = [2.0, 4.0]
tool_speed_mm_s = 2.0
'''


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "sweep.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_every_combination_with_every_planner_once(tmp_path):
    spec = load_sweep_spec(write(tmp_path, GOOD))
    tasks = spec.tasks()
    assert len(tasks) == 2 * 3 * 2 * 2
    assert len({t.key for t in tasks}) == len(tasks)
    combos = {
        (t.parameters["robot.friction.mu"], t.parameters["limits.max_tool_speed_mm_s"])
        for t in tasks
    }
    assert len(combos) == 6
    masses = {t.parameters["robot.payload.mass_kg"] for t in tasks}
    assert len(masses) == 2 and all(0.0 <= m <= 0.5 for m in masses)
    # the same file gives the same tasks (the random draws are seeded): a sweep can resume
    assert [t.key for t in load_sweep_spec(write(tmp_path, GOOD)).tasks()] == [t.key for t in tasks]


def test_a_task_runs_with_its_overrides(tmp_path):
    task = load_sweep_spec(write(tmp_path, GOOD)).tasks()[0]
    row = run_task(task)
    problem = so.load_problem(PROBLEM, task.overrides)
    assert problem.robot.friction.mu == task.parameters["robot.friction.mu"]
    assert row["key"] == task.key and row["planner"] == task.planner
    assert row["status"] != "failed" and row["duration_s"] == pytest.approx(40.0)


@pytest.mark.parametrize("planner", ["toppra", "ruckig"])
def test_an_impossible_task_is_a_row_not_an_exception(tmp_path, planner):
    """A joint speed limit in the wrong units (1e-6 rpm) once took toppra to a 5 GB array
    and ruckig to a ValueError: now a failed row each, quickly."""
    task = load_sweep_spec(write(tmp_path, GOOD)).tasks()[0]
    overrides = {"limits.max_joint_speed_rpm": 1e-6}
    bad = dataclasses.replace(task, planner=planner, parameters=overrides, overrides=overrides)
    row = run_task(bad)
    assert row["status"] == "failed" and math.isnan(row["duration_s"])
    assert row["error"].startswith(f"PlanningError: {planner}")


@pytest.mark.parametrize("name", ["friction_payload", "tool_speed"])
def test_shipped_grid_sweeps_expand(name):
    spec = load_sweep_spec(SWEEPS / f"{name}.toml")
    assert spec.tasks() and spec.name == name


def test_drawn_flap_values_are_parameters_and_overrides(tmp_path):
    tasks = load_sweep_spec(write(tmp_path, FLAPS)).tasks()
    assert len(tasks) == 12 and [t.parameters["flap"] for t in tasks] == list(range(12))
    for task in tasks:
        parameters, overrides = task.parameters, task.overrides
        assert set(parameters) == {
            "flap",
            "flap_size_mm",
            "flap_landmarks",
            "limits.contour_tolerance_mm",
            "limits.max_tool_speed_mm_s",
        }
        assert len(overrides["landmarks"]) == parameters["flap_landmarks"]
        tolerance = parameters["limits.contour_tolerance_mm"]
        limit = parameters["limits.max_tool_speed_mm_s"]
        assert 0.05 <= tolerance <= 0.2 and 2.0 <= limit <= 4.0
        assert overrides["limits.contour_tolerance_mm"] == tolerance
        assert overrides["limits.max_tool_speed_mm_s"] == limit
        problem = so.load_problem(PROBLEM, overrides)
        assert problem.limits.contour_tolerance == pytest.approx(tolerance * 1e-3)
        assert problem.limits.max_tool_speed == pytest.approx(limit * 1e-3)
        # mean tool speed of the durations: 2 mm/s, at most 2/3 of the limit (rounding the
        # durations up to 0.1 s only slows it)
        mean = problem.contour.length * 1e3 / problem.segment_durations.sum()
        assert mean <= min(2.0, DURATION_SPEED_FRACTION * limit) + 1e-9
        assert task.anchor is None  # the flap's limits are part of the cut
    assert {t.parameters["flap_landmarks"] for t in tasks} == {4, 5, 6}
    again = load_sweep_spec(write(tmp_path, FLAPS)).tasks()
    assert [t.key for t in again] == [t.key for t in tasks]


def test_fixed_landmarks_and_no_limits_add_no_parameters(tmp_path):
    text = FLAPS.replace("landmarks = [4, 6]", "landmarks = 5")
    text = "\n".join(line for line in text.splitlines() if "_mm = [0.05" not in line)
    text = text.replace("max_tool_speed_mm_s = [2.0, 4.0]\n", "")
    tasks = load_sweep_spec(write(tmp_path, text)).tasks()
    assert all(set(t.parameters) == {"flap", "flap_size_mm"} for t in tasks)
    assert all(set(t.overrides) == {"landmarks", "segment_durations_s"} for t in tasks)
    assert all(len(t.overrides["landmarks"]) == 5 for t in tasks)


def test_the_shipped_flap_sweep_draws_the_flaps_it_drew_before():
    """random_flaps.toml's flaps, positions (mm), sizes (mm) and segment durations (s), as
    the generator drew them before it learnt landmark ranges and drawn limits."""
    spec = load_sweep_spec(SWEEPS / "random_flaps.toml")
    sets = spec.parameter_sets(so.load_problem(spec.problem_path))
    assert len(sets) == 200
    assert all(set(parameters) == {"flap", "flap_size_mm"} for parameters, _, _ in sets)
    pinned = {
        0: (
            25.368044410263085,
            [[-3.92, -22.12, 66.96], [-5.24, -6.05, 70.17], [-22.01, -7.21, 66.72]]
            + [[-17.79, -26.85, 62.86]],
            [8.3, 8.7, 10.3, 7.7],
        ),
        1: (
            42.5819629123726,
            [[-31.91, 50.79, 36.26], [-48.46, 31.85, 39.35], [-35.11, 14.81, 58.82]]
            + [[-13.36, 33.63, 60.02]],
            [12.8, 14.7, 14.5, 17.6],
        ),
        199: (
            36.10772665523108,
            [[54.74, 11.42, 40.58], [50.18, 32.34, 34.78], [34.04, 37.87, 46.7]]
            + [[30.44, 15.67, 60.01]],
            [11.2, 10.5, 13.2, 15.9],
        ),
    }
    for index, (size_mm, positions_mm, durations_s) in pinned.items():
        parameters, overrides, cut = sets[index]
        assert parameters == {"flap": index, "flap_size_mm": size_mm}
        assert [t["position_mm"] for t in overrides["landmarks"]] == positions_mm
        assert overrides["segment_durations_s"] == durations_s
        assert set(overrides) == {"landmarks", "segment_durations_s"} and cut == overrides


def test_the_shipped_varied_flap_sweep_expands():
    spec = load_sweep_spec(SWEEPS / "random_flaps_varied.toml")
    assert spec.planners == ("toppra", "ocp-min-time", "ocp-min-energy", "ocp-min-jerk")
    sets = spec.parameter_sets(so.load_problem(spec.problem_path))
    assert len(sets) == 200
    table = np.array(
        [
            [
                p["flap_landmarks"],
                p["limits.contour_tolerance_mm"],
                p["limits.max_tool_speed_mm_s"],
            ]
            for p, _, _ in sets
        ]
    )
    assert set(table[:, 0]) == {4, 5, 6}
    assert table[:, 1].min() >= 0.05 and table[:, 1].max() <= 0.2
    assert table[:, 2].min() >= 2.0 and table[:, 2].max() <= 4.0
    assert "ocp-min-energy" in load_sweep_spec(SWEEPS / "random_flaps.toml").planners


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (("landmarks = [4, 6]", "landmarks = [2, 6]"), "flaps.landmarks = [2, 6]: expected"),
        (("landmarks = [4, 6]", "landmarks = [6, 4]"), "flaps.landmarks = [6, 4]: expected"),
        (("landmarks = [4, 6]", "landmarks = [4, 13]"), "flaps.landmarks = [4, 13]: expected"),
        (("landmarks = [4, 6]", "landmarks = [4.5, 6]"), "flaps.landmarks = [4.5, 6]: expec"),
        (("landmarks = [4, 6]", "landmarks = [4]"), "flaps.landmarks = [4]: expected"),
        (("landmarks = [4, 6]", "landmarks = [4, 5, 6]"), "flaps.landmarks = [4, 5, 6]: exp"),
        (("landmarks = [4, 6]", "landmarks = 2"), "flaps.landmarks = 2: expected"),
        (("landmarks = [4, 6]", "landmarks = 13"), "flaps.landmarks = 13: expected"),
        (("landmarks = [4, 6]", "landmarks = 4.5"), "flaps.landmarks = 4.5: expected"),
        (("landmarks = [4, 6]", 'landmarks = "4"'), "flaps.landmarks = '4': expected"),
        (("landmarks = [4, 6]", "landmarks = true"), "flaps.landmarks = True: expected"),
        (("landmarks = [4, 6]", "landmarks = inf"), "flaps.landmarks = inf: expected"),
        (("[0.05, 0.2]", "[0.0, 0.2]"), "flaps.contour_tolerance_mm = [0.0, 0.2]: expected"),
        (("[0.05, 0.2]", "[-0.1, 0.2]"), "flaps.contour_tolerance_mm = [-0.1, 0.2]: expected"),
        (("[0.05, 0.2]", "[0.2, 0.05]"), "flaps.contour_tolerance_mm = [0.2, 0.05]: expected"),
        (("[0.05, 0.2]", "[0.05]"), "flaps.contour_tolerance_mm = [0.05]: expected"),
        (("[0.05, 0.2]", "0.1"), "flaps.contour_tolerance_mm = 0.1: expected"),
        (("[0.05, 0.2]", "[0.05, nan]"), "flaps.contour_tolerance_mm = [0.05, nan]: expected"),
        (("[2.0, 4.0]", "[0.0, 4.0]"), "flaps.max_tool_speed_mm_s = [0.0, 4.0]: expected"),
        (("[2.0, 4.0]", "[4.0, 2.0]"), "flaps.max_tool_speed_mm_s = [4.0, 2.0]: expected"),
        (("[2.0, 4.0]", '["2", "4"]'), "flaps.max_tool_speed_mm_s = ['2', '4']: expected"),
        (
            ("contour_tolerance_mm = [", "contour_tolerance = ["),
            "flaps.contour_tolerance: unknown key; did you mean 'contour_tolerance_mm'?",
        ),
        (
            ("[flaps]", '[grid]\n"limits.max_tool_speed_mm_s" = [2.0, 3.0]\n[flaps]'),
            "flaps.max_tool_speed_mm_s = [2.0, 4.0]: limits.max_tool_speed_mm_s is already an "
            "axis of [grid] or [random]",
        ),
        (
            (
                "[flaps]",
                '[random]\nsamples = 2\n[random.ranges]\n"limits.contour_tolerance_mm"'
                " = [0.05, 0.1]\n[flaps]",
            ),
            "flaps.contour_tolerance_mm = [0.05, 0.2]: limits.contour_tolerance_mm is already",
        ),
    ],
    ids=[
        "landmarks-too-few",
        "landmarks-reversed",
        "landmarks-too-many",
        "landmarks-fraction-in-range",
        "landmarks-one-bound",
        "landmarks-three-bounds",
        "landmarks-2",
        "landmarks-13",
        "landmarks-fraction",
        "landmarks-text",
        "landmarks-boolean",
        "landmarks-infinite",
        "tolerance-zero",
        "tolerance-negative",
        "tolerance-reversed",
        "tolerance-one-bound",
        "tolerance-scalar",
        "tolerance-nan",
        "speed-zero",
        "speed-reversed",
        "speed-text",
        "tolerance-typo",
        "speed-also-in-grid",
        "tolerance-also-random",
    ],
)
def test_bad_flap_tables_are_one_line_errors(tmp_path, edit, expected):
    old, new = edit
    assert old in FLAPS
    with pytest.raises(so.InputError) as caught:
        load_sweep_spec(write(tmp_path, FLAPS.replace(old, new, 1)))
    message = str(caught.value)
    assert expected in message and "\n" not in message


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (
            ('"robot.friction.mu" = [0.04, 0.24]', '"robot.friction.mu" = []'),
            "grid.robot.friction.mu = []: expected a non-empty list",
        ),
        (('"robot.friction.mu"', '"robot.friction.muu"'), "unknown key; did you mean 'mu'?"),
        (("[0.04, 0.24]", "[0.04, -1.0]"), "grid.robot.friction.mu = -1.0"),
        (("[0.04, 0.24]", "[0.04, 0.04]"), "expected each value once"),
        (
            ('"limits.max_tool_speed_mm_s"', '"limits.max_tool_speed_mps"'),
            "limits.max_tool_speed_mps: unknown key",
        ),
        (("[0.0, 0.5]", "[0.5, 0.0]"), "expected [low, high] with low < high"),
        (("samples = 2", "samples = 0"), "random.samples = 0"),
        (("samples = 2", "samples = 2.5"), "expected a whole number"),
        (
            ('["cubic", "ruckig"]', '["cubic", "fast"]'),
            "planners = ['cubic', 'fast']: expected a non-empty list of",
        ),
        (
            ('["cubic", "ruckig"]', '["cubic", "toppr"]'),
            "toppra ('toppr': did you mean 'toppra'?)",
        ),
        (('planners = ["cubic", "ruckig"]', 'planner = ["cubic"]'), "planner: unknown key"),
        (
            ('"robot.friction.mu" = [0.04, 0.24]', '"robot" = ["robots/prototype.toml"]'),
            "grid.robot = 'robots/prototype.toml': the robot file cannot be swept",
        ),
        (
            (f'problem = "{PROBLEM}"', 'problem = "nowhere.toml"'),
            "problem = 'nowhere.toml': no problem file",
        ),
    ],
    ids=[
        "empty-axis",
        "unknown-robot-key",
        "bad-value",
        "twice",
        "unknown-limit",
        "bad-range",
        "no-samples",
        "fractional",
        "unknown-planner",
        "planner-typo",
        "typo-key",
        "robot-file",
        "no-problem",
    ],
)
def test_bad_specs_are_one_line_errors(tmp_path, edit, expected):
    old, new = edit
    assert old in GOOD
    with pytest.raises(so.InputError) as caught:
        load_sweep_spec(write(tmp_path, GOOD.replace(old, new, 1)))
    message = str(caught.value)
    assert expected in message and "\n" not in message


ONE_AXIS = f'''
name = "repeats"
problem = "{PROBLEM}"
planners = ["cubic"]
'''


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (
            ("", '[grid]\n"limits.max_tool_speed_mm_s" = [2, 2.0]\n'),
            "grid.limits.max_tool_speed_mm_s = [2, 2.0]: expected each value once (2 and 2.0 "
            "are one value)",
        ),
        (
            ("", '[grid]\n"limits.max_tool_speed_mm_s" = [3.0, -0.0, 0]\n'),
            "grid.limits.max_tool_speed_mm_s = [3.0, -0.0, 0]: expected each value once (-0.0 "
            "and 0 are one value)",
        ),
        (
            ("", '[grid]\n"limits.max_tool_speed_mm_s" = [2, 2]\n'),
            "grid.limits.max_tool_speed_mm_s = [2, 2]: expected each value once (2 twice)",
        ),
        (
            ('planners = ["cubic"]', 'planners = ["cubic", "toppra", "cubic"]'),
            "planners = ['cubic', 'toppra', 'cubic']: expected each planner once (cubic twice)",
        ),
        (
            ("", '[random]\nsamples = 2\n[random.ranges]\n"limits.max_tool_speed_mm_s" = [4, 2]\n'),
            "random.ranges.limits.max_tool_speed_mm_s = [4.0, 2.0]: expected [low, high] with "
            "low < high",
        ),
    ],
    ids=["equal-numbers", "signed-zero", "same-number", "planner-twice", "plain-numbers"],
)
def test_repeats_and_numbers_in_messages_are_one_plain_line(tmp_path, capsys, edit, expected):
    """A grid value or a planner given twice (2 and 2.0 alike: one problem) is refused
    naming its field, and a message shows numbers as the file wrote them (4.0, not
    np.float64(4.0)): exit status 2, nothing written."""
    old, new = edit
    spec = write(tmp_path, ONE_AXIS.replace(old, new, 1) if old else ONE_AXIS + new)
    out = tmp_path / "out"
    status, shown = run_cli(["sweep", str(spec), "--out", str(out)])
    err = capsys.readouterr().err
    assert_one_error(status, err, (), tmp_path, shown)
    assert err == f"spm-opt: error: {spec}: {expected}\n"
    assert not out.exists()


def test_equal_grid_values_of_every_kind_are_found():
    """Numbers by value, lists item by item, tables key by key; true is not 1, "2" not 2."""
    for values in ([1, 1.0], [[1, 2], [1.0, 2.0]], [{"a": 1}, {"a": 1.0}], [True, True]):
        with pytest.raises(so.InputError, match="expected each value once"):
            _grid(Table({"k": values}, "spec"))
    for values in ([True, 1], ["2", 2], [[1, 2], [2, 1]], [0.1, 0.1 + 1e-12]):
        assert _grid(Table({"k": values}, "spec")) == {"k": values}


def test_a_warm_started_row_does_not_depend_on_what_ran_before(tmp_path):
    """ocp-min-time starts from its anchor's plan (the base problem, planned from scratch
    once per process), so a task gives the same row whichever tasks its worker ran."""
    from spm_opt.studies.sweep import task as task_module

    text = GOOD.replace('["cubic", "ruckig"]', '["ocp-min-time"]')
    text = text[: text.index("[random]")].replace('"robot.friction.mu" = [0.04, 0.24]\n', "")
    first, second = load_sweep_spec(write(tmp_path, text)).tasks()[:2]
    assert first.anchor == {} and second.anchor == {}
    steady = ("wall_time_s", "solve_time_s")

    task_module._anchor_plan.cache_clear()
    alone = run_task(second)
    task_module._anchor_plan.cache_clear()
    run_task(first)
    after = run_task(second)
    assert task_module._anchor_plan.cache_info().hits >= 1
    assert {k: v for k, v in after.items() if k not in steady} == {
        k: v for k, v in alone.items() if k not in steady
    }
    assert alone["status"] == "ok"


def test_a_task_carries_its_files_and_runs_where_they_are_not(tmp_path):
    """The problem names its robot file by ``../robots/...``: a task, run after the
    directory is gone, writes both in that layout and gives the row it gave before; an
    error names the problem file where the runner read it."""
    (tmp_path / "flaps").mkdir()
    text = Path(PROBLEM).read_text().replace('"robots/prototype.toml"', '"../robots/p.toml"')
    (tmp_path / "flaps" / "flap.toml").write_text(text)
    (tmp_path / "robots").mkdir()
    shutil.copy(ROOT / "problems" / "robots" / "prototype.toml", tmp_path / "robots" / "p.toml")
    spec = GOOD.replace(PROBLEM, (tmp_path / "flaps" / "flap.toml").as_posix())
    task = load_sweep_spec(write(tmp_path, spec)).tasks()[0]
    before = run_task(task)
    (tmp_path / "flaps").rename(tmp_path / "elsewhere")
    shutil.rmtree(tmp_path / "robots")
    steady = ("wall_time_s", "solve_time_s")
    after = run_task(task)
    assert after["status"] != "failed", after["error"]
    assert {k: v for k, v in after.items() if k not in steady} == {
        k: v for k, v in before.items() if k not in steady
    }
    bad = dataclasses.replace(task, overrides={"limits.max_tool_speed_mm_s": -1.0})
    row = run_task(bad)
    assert row["failure"] == "result"
    assert row["error"].startswith(f"InputError: {tmp_path / 'flaps' / 'flap.toml'}: limits.")


def test_a_robot_file_named_by_an_absolute_path_is_refused(tmp_path):
    robot = (ROOT / "problems" / "robots" / "prototype.toml").as_posix()
    text = Path(PROBLEM).read_text().replace('"robots/prototype.toml"', f'"{robot}"')
    (tmp_path / "absolute.toml").write_text(text)
    with pytest.raises(so.InputError) as caught:
        load_sweep_spec(write(tmp_path, GOOD.replace(PROBLEM, f"{tmp_path}/absolute.toml")))
    message = str(caught.value)
    assert "robot = " in message and "relative to the problem file" in message
    assert "\n" not in message


def test_a_worker_with_other_code_refuses_the_task(tmp_path):
    task = load_sweep_spec(write(tmp_path, GOOD)).tasks()[0]
    assert task.code == code_identity() and task.code.startswith(f"{so.__version__}+")
    row = run_task(dataclasses.replace(task, code="0.0.1+0123456789abcdef"))
    assert row["status"] == "failed" and row["failure"] == "machine"
    assert row["error"] == (
        f"this worker runs spm_opt {code_identity()}, the task was made by 0.0.1+0123456789abcdef"
    )


def test_anchor_plans_are_kept_by_the_files_contents():
    """Two problem files of one path but other contents have their own anchors."""
    files = ProblemFiles.read(PROBLEM)
    longer = dataclasses.replace(
        files, text=files.text.replace("[10.0, 10.0, 10.0, 10.0]", "[12.0, 12.0, 12.0, 12.0]")
    )
    assert longer.text != files.text and longer.path == files.path
    assert _anchor_plan(files, "cubic", "{}").duration == pytest.approx(40.0)
    assert _anchor_plan(longer, "cubic", "{}").duration == pytest.approx(48.0)
