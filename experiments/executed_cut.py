"""What the robot cuts: every planner's plan executed, with and without the led goals.

    python experiments/executed_cut.py --out docs/executed_cut [--backend sim|emulator]
                                       [--planners toppra,ocp-min-time] [--repeats N]

For ``craniotomy_hardware.toml`` and the paper's ``craniotomy_bone_flap.toml``, each
planner's plan runs on a robot that is not the planning model (the plant is
``problems/robots/prototype_plant.toml``: heavier, with drive friction, rotor inertia and
encoder offsets; and the same with its offsets at zero), once with goals
equal to the plan (``--tracking none``) and once led by the loops' lag (``lead``). Each run
is judged by the evaluator on its log and on the plant's true state
(:func:`spm_opt.verify.executed_cut.evaluate_log`): did it complete, how far the joints
were from the plan (the true tracking error) and how far the true cut was from the
contour, and which robot limits (joint speed, acceleration, jerk, torque, current) the
true run broke. Beside each run, the cut and the broken robot limits predicted before it
(:func:`spm_opt.verify.predicted_cut.predict_cut`) with the plant's own file as the model:
its loops are the file's (the default ωv of 150 1/s), while the plant runs the control
table's default gains (ωv 87 and 116 1/s on that plant). ``--model ROBOT`` predicts on
another robot file instead, such as the one ``spm-opt identify`` wrote from the plant's
own logs (``experiments/identify_prototype.py``'s ``identified.toml``). ``--lab-robot
ROBOT`` is the lab's whole path instead: the problems' robot is replaced by ROBOT
(identified from the plant's logs and calibrated against it by ``spm-opt calibrate``), so
the plans are made on it, the executor reads the encoders through its calibration, and the
cut is predicted on it; the plant with its offsets at zero is then left out, since that
calibration is of the plant with its offsets. With ``--lab-robot`` each plan whose
predicted run breaks a robot limit or takes a joint's margin also runs slowed at its
breakaways, or throughout where no dip keeps them (``spm-opt slow-breakaways`` on ROBOT:
:func:`spm_opt.verify.breakaway.slowed_for_breakaways`), led, and the table gives that
run's pace, its duration, its true cut, the robot limits it broke, and
its worst joint speed, acceleration and jerk against their limits. ``--backend
emulator`` runs the same through the real Dynamixel SDK against the emulated actuators, in
real time (about two minutes; keep the machine otherwise idle:
a loop that stalls for 0.2 s is a following error). ``--repeats N`` makes each run N
times: in real time, when each goal reaches the actuators differs from run to run, and a
table gives each figure's range over the runs against the prediction, which does not
change. Writes ``executed_cut.md``,
``executed_cut.json`` and ``executed_cut.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

import spm_opt as so
from spm_opt.base.errors import CommunicationError
from spm_opt.base.markdown import markdown_table
from spm_opt.cli.run import run_script
from spm_opt.execution.backend import Backend
from spm_opt.execution.results import ExecutionResult
from spm_opt.judge.limits import ROBOT_RULES, contour_tube
from spm_opt.judge.report import Violation
from spm_opt.model.params import DEG, MM, Robot
from spm_opt.report.planner_style import labelled_handles
from spm_opt.verify.breakaway import slowed_for_breakaways
from spm_opt.verify.executed_cut import evaluate_log
from spm_opt.verify.predicted_cut import PredictedCut, predict_cut, worst_by_figure

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ("craniotomy_hardware", "craniotomy_bone_flap")
PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"
TRACKINGS = ("none", "lead")
SLOWED = "slowed"
"""The tracking name of the lead on the plan slowed at its breakaways."""
CONNECT_TRIES = 3
"""How many times a run's connection is made before its failure ends the study."""
FLOOR_MM = 1e-3
"""The figure's floor for a cut's distance from the contour, mm (log scale)."""
_COLOURS = {"none": "tab:blue", "lead": "tab:orange", "plan": "0.6"}
"""The bars' colours: the plan's cut, the true cut with goals unled and led."""


@dataclasses.dataclass(frozen=True)
class Row:
    """One run: the plan, the plant, the tracking and what the judge found (deg, mm)."""

    problem: str
    planner: str
    plant: str
    tracking: str
    completed: bool
    outcome: str
    planned_deviation_mm: float
    true_tracking_error_deg: float
    measured_tracking_error_deg: float
    true_deviation_mm: float
    predicted_deviation_mm: float
    tube_mm: float | None
    violations: int
    true_broken_limits: list[str]
    predicted_broken_limits: list[str]
    duration_s: float
    pace_at_breakaways: float
    worst_share_of_limit: dict[str, float]
    predicted_share_of_limit: dict[str, float]
    slowed_throughout: bool = False
    repeat: int = 0
    late_goals: int = 0
    latest_goal_ms: float = 0.0
    broken_near_late_goals: list[str] = dataclasses.field(default_factory=list)


def _plants(calibrated: bool) -> Iterator[tuple[str, Robot]]:
    """The plant, and unless the lab's robot is ``calibrated`` against it, the plant with
    its encoder offsets at zero (a robot whose zeros are known)."""
    plant = so.load_robot(PLANT)
    yield "prototype_plant", plant
    if not calibrated:
        yield "offsets at zero", dataclasses.replace(plant, encoder_offset=np.zeros(2))


@contextmanager
def _backend(kind: str, problem: so.Problem, plan: so.Trajectory, plant: Robot, trace: Path):
    """A backend whose plant is ``plant``, resting at the plan's start; the plant's true
    state goes to ``trace`` when the block ends."""
    start = plan.position(plan.start_time)
    if kind == "sim":
        backend = so.SimulatedRobot(problem.robot, start_rad=start, plant_robot=plant)
        yield backend
        backend.trace.save(trace)
        return
    from spm_opt.execution.dynamixel import DynamixelRobot
    from spm_opt.execution.emulator import spawn_emulator
    from spm_opt.model.params import robot_toml

    robot_file = trace.with_suffix(".toml")
    robot_file.write_text(robot_toml(plant, plant.name))
    with spawn_emulator(robot_file, start_deg=tuple(start / DEG), trace_path=trace) as emulator:
        yield DynamixelRobot(problem.robot.actuator, emulator.device)


def _executed(
    kind: str,
    problem: so.Problem,
    plan: so.Trajectory,
    plant: Robot,
    tracking: str,
    log: Path,
    trace: Path,
) -> ExecutionResult:
    """The run of ``plan`` on a fresh backend of ``kind`` driving ``plant``, logged to
    ``log`` and ``trace``. A connection that fails before anything moves (a read timing out
    while other work loads the machine) is made again on a fresh backend, up to
    :data:`CONNECT_TRIES` times in all, rather than ending the study."""
    tries = 1
    while True:
        backend: Backend
        try:
            with _backend(kind, problem, plan, plant, trace) as backend:
                return so.execute(plan, backend, problem, log, _settings(tracking))
        except CommunicationError as error:
            if tries == CONNECT_TRIES:
                raise
            tries += 1
            print(f"{log.stem}: connecting failed ({error}); connecting again", file=sys.stderr)


def run_one(
    kind: str,
    problem: so.Problem,
    plan: so.Trajectory,
    plant: tuple[str, Robot],
    tracking: str,
    work: Path,
    predicted: PredictedCut,
    repeat: int = 0,
) -> Row:
    """Execute ``plan`` with ``tracking`` on ``plant`` and judge the run (the ``repeat``-th
    of the same), beside its ``predicted`` cut. Tracking "slowed" is the lead on the plan
    slowed at its breakaways."""
    name = (
        f"{problem.name}-{plan.metadata['planner']}-{plant[0].replace(' ', '_')}-{tracking}"
        f"-{repeat}"
    )
    log, trace = work / f"{name}.csv", work / f"{name}.npz"
    result = _executed(kind, problem, plan, plant[1], tracking, log, trace)
    result.raise_if_signalled()
    reports = evaluate_log(problem, log, trace)
    true = reports.true
    assert true is not None
    tube = contour_tube(problem, executed=True)
    return Row(
        problem=problem.name,
        planner=plan.metadata["planner"],
        plant=plant[0],
        tracking=tracking,
        completed=result.completed,
        outcome=result.reason,
        planned_deviation_mm=so.evaluate(problem, plan).max_contour_deviation_mm,
        true_tracking_error_deg=max(true.max_tracking_error_deg),
        measured_tracking_error_deg=max(reports.measured.max_tracking_error_deg),
        true_deviation_mm=true.max_contour_deviation_mm,
        predicted_deviation_mm=predicted.deviation_mm,
        tube_mm=None if tube is None else tube / MM,
        violations=len(true.violations),
        true_broken_limits=_robot_limits(true.violations),
        predicted_broken_limits=[v.limit for v in predicted.broken_limits],
        duration_s=plan.duration,
        pace_at_breakaways=plan.metadata.get("slowed", {}).get("feed", 1.0),
        slowed_throughout=plan.metadata.get("slowed", {}).get("uniform", False),
        worst_share_of_limit=worst_by_figure(true.limit_shares),
        predicted_share_of_limit=worst_by_figure(predicted.report.limit_shares),
        repeat=repeat,
        late_goals=true.late_goals,
        latest_goal_ms=true.latest_goal_ms,
        broken_near_late_goals=list(true.after_late_goals),
    )


def _settings(tracking: str) -> so.ExecutionSettings:
    """The executor's settings of a run with ``tracking`` ("slowed": the lead)."""
    return so.ExecutionSettings(tracking="lead" if tracking == SLOWED else tracking)


def _robot_limits(violations: list[Violation]) -> list[str]:
    """The robot's limits among ``violations`` ("theta2 jerk"), in the judge's order."""
    return [v.limit for v in violations if v.rule in ROBOT_RULES]


def run(
    kind: str,
    problems: list[str],
    planners: list[str],
    work: Path,
    model: Robot | None,
    lab_robot: Robot | None = None,
    repeats: int = 1,
) -> list[Row]:
    """Every planner's clean plan of each problem, on each plant, with each tracking, run
    ``repeats`` times, the cut predicted on ``model`` (default: each plant's own file). With
    ``lab_robot`` the problems' robot is replaced by it: it plans, calibrates the encoders
    and predicts."""
    rows = []
    calibrated = lab_robot is not None and not lab_robot.calibration.is_ideal
    for problem_name in problems:
        problem = so.load_problem(ROOT / "problems" / f"{problem_name}.toml")
        if lab_robot is not None:
            problem = dataclasses.replace(problem, robot=lab_robot)
        for planner in planners:
            plan = so.plan(problem, planner)
            if so.evaluate(problem, plan).violations:
                print(f"{problem_name} {planner}: not clean, left out", file=sys.stderr)
                continue
            runs = [(tracking, plan) for tracking in TRACKINGS]
            if lab_robot is not None:
                slowed = slowed_for_breakaways(problem, plan, model)
                if slowed.feed < 1.0:  # else the plan's predicted run keeps the limits
                    runs.append((SLOWED, slowed.trajectory))
            for plant in _plants(calibrated):
                for tracking, trajectory in runs:
                    on = model or plant[1]
                    predicted = predict_cut(problem, trajectory, on, _settings(tracking))
                    for repeat in range(repeats):
                        row = run_one(
                            kind, problem, trajectory, plant, tracking, work, predicted, repeat
                        )
                        print(
                            f"{problem_name} {planner} ({plant[0]}, {tracking}, run "
                            f"{repeat + 1}): {'completed' if row.completed else row.outcome}; "
                            f"tracking {row.true_tracking_error_deg:.3f} deg, cut "
                            f"{row.true_deviation_mm:.3f} mm (predicted "
                            f"{row.predicted_deviation_mm:.3f})",
                            file=sys.stderr,
                            flush=True,
                        )
                        rows.append(row)
    return rows


def table(rows: list[Row]) -> str:
    """The runs as markdown: none beside lead for each plan and plant."""
    by_key: dict[tuple[str, str, str], dict[str, Row]] = {}
    for row in _first_runs(rows):
        by_key.setdefault((row.problem, row.planner, row.plant), {})[row.tracking] = row
    lines = []
    for (problem, planner, plant), pair in by_key.items():
        none, lead = pair["none"], pair["lead"]
        lines.append(
            (
                problem,
                planner,
                plant,
                "yes" if none.completed else "no",
                "yes" if lead.completed else "no",
                f"{none.true_tracking_error_deg:.3f}",
                f"{lead.true_tracking_error_deg:.3f}",
                f"{lead.planned_deviation_mm:.3f}",
                f"{none.true_deviation_mm:.3f}",
                f"{lead.true_deviation_mm:.3f}",
                f"{lead.predicted_deviation_mm:.3f}",
                f"{lead.predicted_deviation_mm - lead.true_deviation_mm:+.3f}",
                "—" if lead.tube_mm is None else f"{lead.tube_mm:g}",
                ", ".join(lead.true_broken_limits) or "none",
                ", ".join(lead.predicted_broken_limits) or "none",
            )
        )
    header = (
        "problem",
        "planner",
        "plant",
        "completed (none)",
        "completed (lead)",
        "true tracking error, none (deg)",
        "true tracking error, lead (deg)",
        "planned cut off the contour (mm)",
        "true cut off the contour, none (mm)",
        "true cut off the contour, lead (mm)",
        "predicted, lead (mm)",
        "predicted less true, lead (mm)",
        "tube (mm)",
        "robot limits broken, true (lead)",
        "robot limits broken, predicted (lead)",
    )
    return _table_or_nothing(header, lines)


def slowed_table(rows: list[Row]) -> str:
    """The runs slowed at their breakaways beside the led plan's, as markdown ("" if none)."""
    lines = []
    for slowed in (r for r in _first_runs(rows) if r.tracking == SLOWED):
        lead = next(
            r
            for r in _first_runs(rows)
            if (r.problem, r.planner, r.plant, r.tracking)
            == (slowed.problem, slowed.planner, slowed.plant, "lead")
        )

        def shares(worst: dict[str, float]) -> str:
            return ", ".join(f"{kind} {share:.1%}" for kind, share in worst.items())

        lines.append(
            (
                slowed.problem,
                slowed.planner,
                slowed.plant,
                f"{slowed.pace_at_breakaways:.2f}"
                + (" throughout" if slowed.slowed_throughout else ""),
                f"{lead.duration_s:.1f} → {slowed.duration_s:.1f}",
                "yes" if slowed.completed else "no",
                f"{lead.true_deviation_mm:.3f} → {slowed.true_deviation_mm:.3f}",
                f"{slowed.predicted_deviation_mm - slowed.true_deviation_mm:+.3f}",
                ", ".join(slowed.true_broken_limits) or "none",
                ", ".join(slowed.predicted_broken_limits) or "none",
                shares(lead.worst_share_of_limit),
                shares(slowed.predicted_share_of_limit),
                shares(slowed.worst_share_of_limit),
            )
        )
    header = (
        "problem",
        "planner",
        "plant",
        "pace (at the breakaways, or throughout)",
        "duration, led → slowed (s)",
        "completed (slowed)",
        "true cut, led → slowed (mm)",
        "predicted less true, slowed (mm)",
        "robot limits broken, true (slowed)",
        "robot limits broken, predicted (slowed)",
        "worst joint speed, acceleration, jerk of their limits, true (led)",
        "the same, predicted (slowed)",
        "the same, true (slowed)",
    )
    return _table_or_nothing(header, lines)


def repeats_table(rows: list[Row]) -> str:
    """Each run made more than once: its predicted worst joint speed, acceleration and jerk
    against their limits beside the true runs' range, and the true cut's range, as markdown
    ("" if no run was repeated)."""
    runs: dict[tuple[str, str, str, str], list[Row]] = {}
    for row in rows:
        runs.setdefault((row.problem, row.planner, row.plant, row.tracking), []).append(row)
    lines = []
    for key, repeated in runs.items():
        if len(repeated) < 2:
            continue
        predicted = repeated[0].predicted_share_of_limit
        cells = []
        for figure, share in predicted.items():
            true = [r.worst_share_of_limit[figure] for r in repeated]
            cells.append(
                f"{figure} {share:.1%}: {min(true):.1%}–{max(true):.1%} "
                f"(×{min(true) / share:.3f}–{max(true) / share:.3f})"
            )
        cuts = [r.true_deviation_mm for r in repeated]
        late = [r for r in repeated if r.late_goals]
        beyond = [(r, limits) for r in repeated if (limits := set(_beyond_prediction(r)))]
        near = [r for r, limits in beyond if limits <= set(r.broken_near_late_goals)]
        lines.append(
            (
                *key,
                str(len(repeated)),
                f"{sum(r.completed for r in repeated)}",
                "; ".join(cells),
                f"{repeated[0].predicted_deviation_mm:.4f}: {min(cuts):.4f}–{max(cuts):.4f}",
                f"{len(late)}" + (f" ({max(r.latest_goal_ms for r in late):.1f})" if late else ""),
                f"{len(beyond)} ({len(near)})",
            )
        )
    header = (
        "problem",
        "planner",
        "plant",
        "tracking",
        "runs",
        "completed",
        "worst joint figure of its limit, predicted: true, least–most (true over predicted)",
        "cut off the contour, predicted: true, least–most (mm)",
        "runs with a goal late (the latest, ms)",
        "runs breaking a robot limit their prediction kept (each such limit near a late goal)",
    )
    return _table_or_nothing(header, lines)


def _beyond_prediction(row: Row) -> list[str]:
    """The robot limits ``row``'s true run broke that its prediction kept."""
    return [limit for limit in row.true_broken_limits if limit not in row.predicted_broken_limits]


def _table_or_nothing(header: tuple[str, ...], lines: list[tuple[str, ...]]) -> str:
    """The lines under the header as markdown, or "" if there are none."""
    return "\n".join(markdown_table(header, lines)) if lines else ""


def _first_runs(rows: list[Row]) -> list[Row]:
    """Each run's first making, of ``rows``."""
    return [r for r in rows if r.repeat == 0]


def figure(rows: list[Row], path: Path) -> None:
    """Per problem (a row of panels), on the plant prototype_plant.toml: the largest true
    tracking error (deg) and the true cut's largest distance from the contour (mm, log
    scale, beside the plan's own and the tube), with the goals unled and led, per planner.
    Written to ``path`` as PNG."""
    problems = list(dict.fromkeys(r.problem for r in rows))
    fig = Figure(figsize=(13, 4.2 * len(problems) + 0.6), layout="constrained")
    axes = fig.subplots(len(problems), 2, squeeze=False)
    for (tracking, cut), problem in zip(axes, problems, strict=True):
        mine = [
            r for r in _first_runs(rows) if r.problem == problem and r.plant == "prototype_plant"
        ]
        _tracking_bars(tracking, mine)
        _cut_bars(cut, mine)
        tracking.set_title(f"{problem}: largest true tracking error", fontsize=10)
        cut.set_title(
            f"{problem}: the cut off the contour (floor {FLOOR_MM:g} mm)",
            fontsize=10,
        )
    handles = labelled_handles(axes.ravel())
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncol=len(handles))
    fig.suptitle("Each plan executed on the plant (prototype_plant.toml), judged on its true state")
    fig.savefig(path, dpi=120, bbox_inches="tight")


def _value(rows: list[Row], planner: str, tracking: str, field: str) -> float:
    return next(getattr(r, field) for r in rows if r.planner == planner and r.tracking == tracking)


def _tracking_bars(axis: Axes, rows: list[Row]) -> None:
    """The largest true tracking error per planner (deg), goals unled and led."""
    planners = list(dict.fromkeys(r.planner for r in rows))
    x = np.arange(len(planners))
    for offset, tracking in ((-0.2, "none"), (0.2, "lead")):
        values = [_value(rows, p, tracking, "true_tracking_error_deg") for p in planners]
        axis.bar(x + offset, values, 0.4, label=f"goals: {tracking}", color=_COLOURS[tracking])
    axis.set_xticks(x, planners, rotation=30, ha="right")
    axis.set_ylabel("largest true tracking error (deg)")
    axis.grid(True, axis="y", alpha=0.3)


def _cut_bars(axis: Axes, rows: list[Row]) -> None:
    """The plan's and the true cuts' largest distance from the contour per planner (mm, log
    scale, at least :data:`FLOOR_MM`), the predicted cut's with the lead, and the tube if
    the problem has one."""
    planners = list(dict.fromkeys(r.planner for r in rows))
    x = np.arange(len(planners))
    planned = [_value(rows, p, "lead", "planned_deviation_mm") for p in planners]
    axis.bar(
        x - 0.27,
        np.maximum(planned, FLOOR_MM),
        0.27,
        label="the plan's own cut",
        color=_COLOURS["plan"],
    )
    for offset, tracking in ((0.0, "none"), (0.27, "lead")):
        values = [_value(rows, p, tracking, "true_deviation_mm") for p in planners]
        axis.bar(x + offset, np.maximum(values, FLOOR_MM), 0.27, color=_COLOURS[tracking])
    predicted = [_value(rows, p, "lead", "predicted_deviation_mm") for p in planners]
    axis.plot(
        x + 0.27,
        np.maximum(predicted, FLOOR_MM),
        "kD",
        markersize=6,
        label="predicted before the run (lead)",
    )
    tube = rows[0].tube_mm
    if tube is not None:
        axis.axhline(tube, color="black", linestyle="--", linewidth=1, label="tube")
    axis.set_yscale("log")
    axis.set_ylim(bottom=FLOOR_MM / 2)
    axis.set_xticks(x, planners, rotation=30, ha="right")
    axis.set_ylabel("largest distance from the contour (mm)")
    axis.grid(True, axis="y", alpha=0.3)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="directory for the report")
    parser.add_argument("--backend", choices=("sim", "emulator"), default="sim")
    parser.add_argument(
        "--problems", default=",".join(PROBLEMS), help="comma-separated problem names"
    )
    parser.add_argument(
        "--planners",
        default="cubic,toppra,ocp-min-time,ocp-min-energy,ocp-min-jerk,ocp-mix,ruckig",
        help="comma-separated planner names",
    )
    parser.add_argument(
        "--model",
        type=Path,
        help="the robot file the predictions run on (default: the plant's own file), e.g. "
        "one spm-opt identify wrote from the plant's logs",
    )
    parser.add_argument(
        "--lab-robot",
        type=Path,
        help="the lab's robot file, identified from the plant and calibrated against it: "
        "it replaces the problems' robot, so it plans, calibrates the encoders and predicts",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=1,
        help="how many times each run is made (through the emulator, in real time, the "
        "goals' timing differs from run to run), from 1 to 20",
    )
    args = parser.parse_args(argv)
    if not 1 <= args.repeats <= 20:
        parser.error(f"--repeats {args.repeats}: expected a whole number from 1 to 20")
    if args.lab_robot is not None and args.model is not None:
        parser.error("--model: not with --lab-robot, which is also the prediction's model")
    lab_robot = None if args.lab_robot is None else so.load_robot(args.lab_robot)
    model = lab_robot if args.model is None else so.load_robot(args.model)
    problems, planners = args.problems.split(","), args.planners.split(",")
    unknown = [name for name in planners if name not in so.PLANNERS]
    if unknown:
        parser.error(
            f"--planners {args.planners}: unknown {', '.join(unknown)}; expected "
            f"some of {', '.join(sorted(so.PLANNERS))}"
        )
    missing = [name for name in problems if not (ROOT / "problems" / f"{name}.toml").is_file()]
    if missing:
        parser.error(f"--problems {args.problems}: no problems/{missing[0]}.toml")
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as work:
        rows = run(args.backend, problems, planners, Path(work), model, lab_robot, args.repeats)
    data: list[dict[str, Any]] = [dataclasses.asdict(r) for r in rows]
    (args.out / "executed_cut.json").write_text(json.dumps(data, indent=2) + "\n")
    predicted_on = "" if args.model is None else f" --model {args.model}"
    if args.lab_robot is not None:
        predicted_on = f" --lab-robot {args.lab_robot}"
    model_file = args.lab_robot or args.model
    text = (
        f"# The executed cut ({args.backend})\n\n"
        "`python experiments/executed_cut.py --out DIR --backend "
        f"{args.backend} --planners {args.planners}{predicted_on}"
        + ("" if args.problems == ",".join(PROBLEMS) else f" --problems {args.problems}")
        + ("" if args.repeats == 1 else f" --repeats {args.repeats}")
        + "` wrote this. "
        + ("" if args.lab_robot is None else f"Planned and calibrated on `{model_file}`. ")
        + "Predicted on "
        + ("each plant's own file" if model is None else f"`{model_file}`")
        + ".\n\n"
        + table(rows)
        + "\n"
    )
    slowed = slowed_table(rows)
    if slowed:
        text += (
            "\nEach plan slowed at its breakaways (or throughout, where no dip keeps the "
            "limits) on the same robot file, led (`spm-opt slow-breakaways`):\n\n" + slowed + "\n"
        )
    repeated = repeats_table(rows)
    if repeated:
        text += (
            f"\nEach run made {args.repeats} times (the tables above give the first):\n\n"
            + repeated
            + "\n"
        )
    (args.out / "executed_cut.md").write_text(text)
    figure(rows, args.out / "executed_cut.png")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
