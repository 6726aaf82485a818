"""``spm-opt calibrate`` end to end: the designed poses run through the one executor on a
simulated robot the model does not know, watched by the simulated tracker, fitted, and the
calibrated robot then cutting inside the tube.

The simulated robot's encoder zeros and mechanism are drawn here; nothing in the fit knows
them. The simulated tracker's recording is on the log's clock; the lab's test moves it by
an offset, since a real tracker shares no clock with the robot.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import ROOT

import spm_opt as so
from spm_opt.cli import main
from spm_opt.execution.log import read_execution_log
from spm_opt.model.geometry import Geometry
from spm_opt.model.params import load_robot, robot_toml
from spm_opt.verify.executed_cut import evaluate_log

PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"
PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"


@pytest.fixture(scope="module")
def unknown_robot(tmp_path_factory):
    """A plant with encoder zeros and error angles the model does not know, its file, and
    the calibration ``spm-opt calibrate`` made of it (12 poses, 4 held out)."""
    folder = tmp_path_factory.mktemp("calibrate")
    rng = np.random.default_rng(42)
    truth = Geometry.from_vector(
        np.radians(np.concatenate([rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.3, 0.3, 5)]))
    )
    plant = dataclasses.replace(
        load_robot(PLANT), encoder_offset=truth.encoder_zero, mechanism=truth.mechanism
    )
    plant_file = folder / "plant.toml"
    plant_file.write_text(robot_toml(plant, "unknown_plant"))
    out = folder / "calibrated.toml"
    status = main(
        [
            "calibrate",
            "--problem",
            str(PROBLEM),
            "--plant-robot",
            str(plant_file),
            "--poses",
            "12",
            "--held-out",
            "4",
            "--out",
            str(out),
        ]
    )
    assert status == 0
    return folder, truth, out


def fit_from_files(folder, tracker, out) -> int:
    """``spm-opt calibrate`` on the fixture's run log and ``tracker``, writing ``out``."""
    log = folder / "calibrated_run.csv"
    arguments = ["--problem", str(PROBLEM), "--log", str(log), "--tracker", str(tracker)]
    return main(["calibrate", *arguments, "--out", str(out)])


def test_calibrate_recovers_an_unknown_robot_and_writes_its_file(unknown_robot):
    """The zeros within three of the standard errors the file states (one draw of the
    tracker's noise: over seeds 0–3 the errors were 0.0006–0.0113°, the standard errors
    0.003–0.008°), and those under 0.01°."""
    folder, truth, out = unknown_robot
    robot = load_robot(out)
    record = robot.calibration_record
    zeros_error = np.degrees(np.abs(robot.calibration.encoder_zero - truth.encoder_zero))
    stated = np.array([record["standard_error_deg"][f"encoder_zero_{j}"] for j in (1, 2)])
    assert np.all(stated < 0.01) and np.all(zeros_error < 3.0 * stated), (zeros_error, stated)
    assert np.allclose(robot.encoder_offset, robot.calibration.encoder_zero)
    assert record["poses"] == 12 and record["held_out_poses"] == 4
    assert 0.0 < record["held_out_rms_mm"] < 0.1
    assert len(record["data_sha256"]) == 64 and record["unidentified"] == []
    assert set(record["standard_error_deg"]) >= {"encoder_zero_1", "encoder_zero_2"}
    report = out.with_suffix(".md").read_text()
    assert "Held-out error (TRE, measured)" in report
    assert out.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"
    assert (folder / "calibrated_run.csv").is_file()


def test_a_labs_log_and_tracker_file_give_the_same_fit(unknown_robot, tmp_path):
    folder, _, out = unknown_robot
    lines = _lines(folder / "calibrated_tracker.csv")
    shifted = [lines[0]] + [
        f"{float(t) + 1234.5:.6f},{rest}" for t, rest in (line.split(",", 1) for line in lines[1:])
    ]
    tracker = tmp_path / "tracker.csv"
    tracker.write_text("\n".join(shifted) + "\n")  # the tracker's own clock
    lab = tmp_path / "lab.toml"
    assert fit_from_files(folder, tracker, lab) == 0
    simulated, from_files = load_robot(out), load_robot(lab)
    assert np.allclose(simulated.calibration.vector(), from_files.calibration.vector(), atol=1e-12)


def _dwell_times(folder, pose):
    """When the run dwelt at ``pose`` (0-based), on the log's clock, s."""
    table, header = read_execution_log(folder / "calibrated_run.csv")
    start, end = header["plan"]["calibration"]["windows_s"][pose]
    rows = table[(table["plan_time_s"] >= start) & (table["plan_time_s"] <= end)]
    return rows["time_s"].min(), rows["time_s"].max()


def _lines(path):
    return path.read_text().splitlines()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("centimetres", "length units"),
        ("hidden", "pose 5: 0 tracker samples in its dwell"),
        ("other run", "do not line up"),
    ],
)
def test_bad_tracker_files_get_one_line(unknown_robot, tmp_path, capsys, change, message):
    folder, _, _ = unknown_robot
    lines = _lines(folder / "calibrated_tracker.csv")
    header, rows = lines[0], [line.split(",") for line in lines[1:]]
    if change == "centimetres":  # exported in cm, read as mm
        rows = [[r[0], *(f"{float(v) / 10:.6f}" if v else "" for v in r[1:])] for r in rows]
    elif change == "hidden":  # the marker hidden through the fifth pose's dwell
        times = np.array([float(r[0]) for r in rows])
        start, end = _dwell_times(folder, 4)
        hide = (times > start + 0.05) & (times < end - 0.05)
        rows = [[r[0], "", "", ""] if h else r for r, h in zip(rows, hide, strict=True)]
    else:  # the robot still throughout: not a recording of this run
        rows = [[r[0], *rows[0][1:]] for r in rows]
    tracker = tmp_path / "tracker.csv"
    tracker.write_text("\n".join([header, *(",".join(r) for r in rows)]) + "\n")
    status = fit_from_files(folder, tracker, tmp_path / "robot.toml")
    error = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert len(error) == 1 and message in error[0], error
    assert not (tmp_path / "robot.toml").exists()


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--poses", "3"], "--poses 3: allowed 6 to 400"),
        (["--log", "run.csv"], "--log and --tracker: give both"),
        (["--tracker-fle-mm", "-1"], "--tracker-fle-mm -1"),
        (["--out", "robot.json"], "ending in .toml"),
    ],
)
def test_bad_arguments_get_one_line(tmp_path, capsys, arguments, message):
    base = ["calibrate", "--problem", str(PROBLEM)]
    if "--out" not in arguments:
        base += ["--out", str(tmp_path / "robot.toml")]
    status = main(base + arguments)
    error = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(error) == 1 and message in error[0], error
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_the_calibrated_prototype_plant_cuts_the_papers_flap_inside_the_tube(tmp_path):
    """prototype_plant.toml's encoder zeros (0.05°, −0.03°) put the paper's flap outside
    its 0.1 mm tube; calibrated, every clean plan's true cut is inside."""
    out = tmp_path / "calibrated.toml"
    assert (
        main(
            ["calibrate", "--problem", str(PROBLEM), "--plant-robot", str(PLANT), "--out", str(out)]
        )
        == 0
    )
    plant = load_robot(PLANT)
    problem = so.load_problem(PROBLEM)
    calibrated = dataclasses.replace(problem, robot=load_robot(out))
    tube = 0.1
    worst = {}
    for label, model in (("uncalibrated", problem), ("calibrated", calibrated)):
        for planner in ("toppra", "ocp-min-time"):
            plan = so.plan(model, planner)
            start = plan.position(0.0) - plant.encoder_offset
            backend = so.SimulatedRobot(model.robot, start_rad=start, plant_robot=plant)
            log = tmp_path / f"{label}_{planner}.csv"
            assert so.execute(plan, backend, model, log).completed
            backend.trace.save(log.with_suffix(".npz"))
            true = evaluate_log(model, log, log.with_suffix(".npz")).true
            worst[label, planner] = true.max_contour_deviation_mm
    assert worst["uncalibrated", "ocp-min-time"] > tube  # the offsets alone leave the tube
    assert all(worst["calibrated", p] < tube for p in ("toppra", "ocp-min-time")), worst
    assert math.isfinite(worst["calibrated", "toppra"])
