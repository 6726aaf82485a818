"""How far and how long a feed hold from full feed takes: on the paper's plan, and on the
time-optimal plans of the hardware problem (the planners keep a hold its room there).

The paper's plan (the cubic via-point trajectory of Tables II–III, 10 s per segment,
40 s) runs on the simulated robot whose plant is not the planning model
(problems/robots/prototype_plant.toml). In each run the operator asks for a hold at one
time of the plan, at full feed, and resumes 1.5 s later; the holds are spread evenly over
the plan. The executor checks the plan against problems/craniotomy_hardware.toml (the same
landmarks and robot): the paper's own problem sets a 10 rad/s³ jerk limit that the plan's
step of acceleration from rest already breaks, so the executor refuses the plan there.

Measured for each hold, from the log and the plant's true state (its trace):

- feed to 0: from the request to the cycle whose feed is 0, s;
- goal's stop: how far the goal's cut point moved along the plan's cut meanwhile, mm;
- true rest: from the request to the first true sample after which the plant's speeds
  stay below the executor's rest speed until the resume, s;
- tool's stop: the true cut point's path length from the request to that rest, mm;
- rest confirmed: from the request to the executor's proof of rest (its rest window), s;
- off the path: the true cut's largest distance from the plan's cut, request to resume, mm.

The same holds, spread over all but the last 0.5 s of each, on toppra's and ocp-min-time's
plans of problems/craniotomy_hardware.toml (made for it: at its joint limits less the room
a hold within its ``hold_within_s`` needs, :mod:`spm_opt.judge.hold_room`), summed up as the
least, median and largest time to rest.

    python experiments/feed_hold.py [--holds 20] [--optimal-holds N] [--out DIR]

writes DIR/feed_hold.md, feed_hold.json (the paper's plan), feed_hold_optimal.json (the
time-optimal plans, by planner) and feed_hold.png (default docs/feed_hold).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

import spm_opt as so
from spm_opt.base.files import write_atomically
from spm_opt.base.markdown import markdown_table
from spm_opt.cli.run import run_script
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot, read_log
from spm_opt.model import kinematics
from spm_opt.model.params import MM, load_robot
from spm_opt.report.plots import to_png

if TYPE_CHECKING:
    from matplotlib.figure import Figure

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "problems" / "craniotomy_bone_flap.toml"
LIMITS = ROOT / "problems" / "craniotomy_hardware.toml"
PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"
RESUME_AFTER_S = 1.5
TIME_OPTIMAL = ("toppra", "ocp-min-time")
SETTINGS = ExecutionSettings(other_problem=True)
"""The paper's plan is made for the paper's problem, whose jerk limit its acceleration step
from rest breaks; it runs here under craniotomy_hardware.toml's limits (the same landmarks
and robot), which the executor allows only when asked."""


class _Operator(SimulatedRobot):
    """The simulated robot with an operator who holds ``hold_s`` after the plan's first
    cycle and resumes later (times on the backend's clock)."""

    executor: Executor
    hold_s: float
    _plan_start: float | None = None
    _last_read: float = 0.0
    _held: bool = False

    def read(self) -> so.execution.Measurement:
        measurement = super().read()
        now, status = self.clock.now(), self.executor.status
        if self._plan_start is None and status is not None and status.phase == "plan":
            self._plan_start = self._last_read  # the plan's first cycle read there
        self._last_read = now
        if self._plan_start is None:
            return measurement
        if now >= self._plan_start + self.hold_s and not self._held:
            self._held = True
            self.executor.hold()
        if now >= self._plan_start + self.hold_s + RESUME_AFTER_S and self._held:
            self.executor.resume()
        return measurement


def cut(problem: so.Problem, q: np.ndarray) -> np.ndarray:
    """Cut points on the skull (N, 3), m, for joint angles q (N, 2)."""
    return problem.contour.cut_points(kinematics.forward_kinematics(q, 1.0))


def path_length(points: np.ndarray) -> float:
    """Length of a polyline (N, 3), m."""
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def one_hold(problem, plan, plant, hold_s: float, log: Path) -> dict:
    """Run the plan with one hold at ``hold_s``; the measurements of the module's doc."""
    backend = _Operator(problem.robot, start_rad=plan.position(0.0), plant_robot=plant)
    backend.executor = Executor(problem, backend, SETTINGS)
    backend.hold_s = hold_s
    result = backend.executor.run(plan, log)
    _, header = read_log(log)
    events = {e["event"]: e for e in header["feed_events"]}
    asked, held = events["hold"], events["held"]
    trace = backend.trace.arrays()
    t, q, v = trace["time_s"], trace["position_rad"], trace["velocity_rad_s"]
    resumed = events["resume"]["time_s"]
    window = (t >= asked["time_s"]) & (t <= resumed)
    moving = np.flatnonzero(window & np.any(np.abs(v) >= SETTINGS.rest_speed_rad_s, axis=1))
    rest_row = moving[-1] + 1
    goal_tau = np.linspace(asked["plan_time_s"], held["plan_time_s"], 200)
    true_cut = cut(problem, q[np.flatnonzero(window)[0] : rest_row + 1])
    dense = np.arange(0.0, plan.duration, 1e-4)
    distance = cKDTree(cut(problem, plan.position(dense))).query(cut(problem, q[window]))[0]
    return {
        "hold_s": hold_s,
        "completed": result.completed,
        "tool_speed_mm_s": float(
            problem.contour.joint_tool_speed(
                plan.position([asked["plan_time_s"]]), plan.velocity([asked["plan_time_s"]])
            )[0]
            / MM
        ),
        "feed_to_zero_s": held["time_s"] - asked["time_s"],
        "goal_stop_mm": path_length(cut(problem, plan.position(goal_tau))) / MM,
        "true_rest_s": float(t[rest_row] - asked["time_s"]),
        "tool_stop_mm": path_length(true_cut) / MM,
        "rest_confirmed_s": events["at rest"]["time_s"] - asked["time_s"],
        "off_path_mm": float(np.max(distance) / MM),
    }


COLUMNS = (
    ("hold at, s", "hold_s", "{:.1f}"),
    ("tool speed, mm/s", "tool_speed_mm_s", "{:.2f}"),
    ("feed to 0, s", "feed_to_zero_s", "{:.2f}"),
    ("goal's stop, mm", "goal_stop_mm", "{:.3f}"),
    ("true rest, s", "true_rest_s", "{:.2f}"),
    ("tool's stop, mm", "tool_stop_mm", "{:.3f}"),
    ("rest confirmed, s", "rest_confirmed_s", "{:.2f}"),
    ("off the path, mm", "off_path_mm", "{:.4f}"),
)


SUMMED = (
    ("feed to 0, s", "feed_to_zero_s", "{:.2f}"),
    ("true rest, s", "true_rest_s", "{:.2f}"),
    ("goal's stop, mm", "goal_stop_mm", "{:.2f}"),
    ("off the path, mm", "off_path_mm", "{:.3f}"),
)


def optimal_report(problem: so.Problem, optimal: dict[str, tuple[float, list[dict]]]) -> list[str]:
    """The time-optimal plans' holds: least / median / largest of each figure."""
    table = []
    for name, (duration, rows) in optimal.items():
        figures = [
            " / ".join(fmt.format(f([r[key] for r in rows])) for f in (np.min, np.median, np.max))
            for _, key, fmt in SUMMED
        ]
        done = all(r["completed"] for r in rows)
        table.append([name, f"{duration:.2f}", f"{len(rows)} ({done})", *figures])
    return [
        "## Holds on the time-optimal plans of the hardware problem",
        "",
        f"The same holds on the plans of {' and '.join(optimal)} for craniotomy_hardware.toml "
        f"(hold_within_s = {problem.limits.hold_within_s:g} s), spread over all but the "
        "last 0.5 s of each; least / median / largest:",
        "",
        *markdown_table(
            ["plan", "duration, s", "holds (all completed)", *(c[0] for c in SUMMED)], table
        ),
        "",
    ]


def report(rows: list[dict], optimal: list[str]) -> str:
    table = [[fmt.format(row[key]) for _, key, fmt in COLUMNS] for row in rows]
    summary = [
        [name, *(fmt.format(f(np.array([r[key] for r in rows]))) for _, key, fmt in COLUMNS[1:])]
        for name, f in (("median", np.median), ("largest", np.max))
    ]
    return "\n".join(
        [
            "# A feed hold from full feed on the paper's plan",
            "",
            f"`python experiments/feed_hold.py --holds {len(rows)}`: the paper's 40 s cubic "
            "plan on the simulated robot (plant: prototype_plant.toml), one hold per run "
            f"from full feed, resumed {RESUME_AFTER_S:g} s later; every run completed: "
            f"{all(r['completed'] for r in rows)}.",
            "",
            *markdown_table([c[0] for c in COLUMNS], table),
            "",
            *markdown_table(["", *(c[0] for c in COLUMNS[1:])], summary),
            "",
            *optimal,
        ]
    )


def figure(rows: list[dict]) -> Figure:
    """Each hold's stopping distance (mm) and times (s) against when along the paper's plan
    it was asked for (s), legends beside the panels."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 5.5), layout="constrained")
    distance, time = fig.subplots(2, 1, sharex=True)
    at = [r["hold_s"] for r in rows]
    distance.plot(at, [r["goal_stop_mm"] for r in rows], "o-", label="goal")
    distance.plot(at, [r["tool_stop_mm"] for r in rows], "s--", label="tool (true)")
    distance.set_ylabel("stopping distance (mm)")
    distance.set_title("how far the cut goes on after the request", fontsize=10)
    time.plot(at, [r["feed_to_zero_s"] for r in rows], "o-", label="feed to 0")
    time.plot(at, [r["true_rest_s"] for r in rows], "s--", label="tool at rest (true)")
    time.plot(at, [r["rest_confirmed_s"] for r in rows], "^:", label="rest confirmed")
    time.set_ylabel("time after the request (s)")
    time.set_title("how long it takes", fontsize=10)
    time.set_xlabel("time of the hold along the paper's plan (s)")
    for axis in (distance, time):
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    fig.suptitle(
        f"A feed hold from full feed on the paper's plan ({len(rows)} runs, one hold "
        "each; plant: prototype_plant.toml)"
    )
    return fig


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--holds", type=int, default=20, help="number of runs, one hold each")
    parser.add_argument(
        "--optimal-holds", type=int, help="runs on each time-optimal plan (default: --holds)"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "feed_hold")
    args = parser.parse_args()
    plan = so.plan(so.load_problem(PAPER), "cubic")
    problem = so.load_problem(LIMITS)
    plant = load_robot(PLANT)
    rows = []
    with TemporaryDirectory() as scratch:
        for k in range(args.holds):
            hold_s = (k + 0.5) / args.holds * plan.duration
            rows.append(one_hold(problem, plan, plant, hold_s, Path(scratch) / f"{k}.csv"))
            print(f"hold {k + 1}/{args.holds} at {hold_s:.1f} s", file=sys.stderr, flush=True)
        optimal, count = {}, args.optimal_holds or args.holds
        for name in TIME_OPTIMAL:
            fast = so.plan(problem, name)
            times = (np.arange(count) + 0.5) / count
            optimal[name] = (
                fast.duration,
                [
                    one_hold(problem, fast, plant, hold_s, Path(scratch) / f"{name}{k}.csv")
                    for k, hold_s in enumerate(times * (fast.duration - 0.5))
                ],
            )
            print(f"{count} holds on {name}'s plan", file=sys.stderr, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    files = {
        args.out / "feed_hold.md": report(rows, optimal_report(problem, optimal)),
        args.out / "feed_hold.json": json.dumps(rows, indent=2) + "\n",
        args.out / "feed_hold_optimal.json": json.dumps(
            {name: held for name, (_, held) in optimal.items()}, indent=2
        )
        + "\n",
        args.out / "feed_hold.png": to_png(figure(rows)),
    }
    write_atomically(files)
    for path in files:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
