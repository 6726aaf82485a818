"""The cut on robots that are not the model: identify → plan → predict → execute, with the
lead alone and with the stream compensated on the identified model.

    python experiments/compensated_cut.py --out docs/compensated_cut [--plants 10]
        [--flaps craniotomy_bone_flap,craniotomy_five_landmarks] [--speed-mm-s 4]
        [--tube-mm 0.12] [--planners toppra,ocp-min-jerk] [--iterations 2]
        [--fit-seconds 30] [--part 0/1]

Each plant is drawn from the family around ``prototype.toml``
(:class:`~spm_opt.verify.plant_family.PlantFamily`, seed 2026: masses, mass-centre radii,
friction, gear losses, rotor inertia and the loops' gains within their ranges) and
identified from its own excitation log on the simulated robot (the robot file ``spm-opt
identify`` would write, its loops estimated from the same log). Every flap is planned once
on the planning model, at ``--speed-mm-s`` with a ``--tube-mm`` tube. For each plant, flap
and planner: the cut predicted on the identified file, the plan executed on the plant (its
true cut from the plant's true state), the stream compensated on the identified file
(:func:`~spm_opt.verify.compensation.compensate`) and executed again. ``--part k/n``
takes every n-th plant from the k-th (for two processes on two cores); ``--merge`` joins
the parts' JSON into the tables (and refuses a part an older version of the study wrote).
Writes ``compensated_cut.json`` (or a part's), and with all parts ``compensated_cut.md``,
``compensated_cut.png`` (the cuts) and ``compensated_cut_limits.png`` (each true run's
share of the joints' limits against its prediction's: the margin's measure) into
``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.figure import Figure

import spm_opt as so
from spm_opt.base.markdown import markdown_table
from spm_opt.cli.run import run_script
from spm_opt.execution import ExecutionSettings
from spm_opt.identify.robot_file import robot_file_text
from spm_opt.judge.limits import ROBOT_RULES, contour_tube
from spm_opt.model.params import MM
from spm_opt.studies.identified_plants import identify_plant
from spm_opt.verify.breakaway import slowed_for_breakaways
from spm_opt.verify.compensation import compensate
from spm_opt.verify.executed_cut import evaluate_log
from spm_opt.verify.plant_family import PlantFamily
from spm_opt.verify.predicted_cut import (
    LIMIT_SHARES,
    PredictedCut,
    highest_feed_inside,
    past_margin,
    predict_cut,
    worst_by_figure,
)

ROOT = Path(__file__).resolve().parents[1]
IDENTIFICATION = ROOT / "problems" / "identification.toml"
IDENTIFY_RUN = ExecutionSettings(
    rate_hz=100.0, current_reads_per_cycle=10, max_following_error_rad=np.radians(5.0)
)
"""The excitation's run, as experiments/identification_coverage.py runs it."""

ROWS_LAYOUT = 2
"""The layout of a part's rows (a part's ``rows_layout``); ``--merge`` refuses a part of
another, written by an older version of this study."""
MARGIN_FLOOR = 0.5
"""The margin is measured on the joints' figures predicted at this share of their limit or
more, where a margin matters."""


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def excitation(seconds: float, seed: int) -> so.Trajectory:
    """identification.toml's excitation of ``seconds`` in 10 s periods."""
    options = {
        "duration_s": 10.0 * max(1, round(seconds / 10.0)),
        "periods": max(1, round(seconds / 10.0)),
        "seed": seed,
        "max_iterations": 60,
    }
    problem = so.load_problem(IDENTIFICATION, {"planner.excitation": options})
    return so.plan(problem, "excitation")


def true_run(
    problem: so.Problem,
    plan: so.Trajectory,
    plant,
    work: Path,
    name: str,
    settings: ExecutionSettings | None = None,
) -> dict:
    """``plan`` executed on ``plant`` with ``settings`` (default: the defaults): completed,
    the true cut (mm), the true run's broken rules."""
    backend = so.SimulatedRobot(
        problem.robot,
        start_rad=plan.position(plan.start_time),
        settings=plant.settings,
        plant_robot=plant.robot,
    )
    log = work / f"{name}.csv"
    result = so.execute(plan, backend, problem, log, settings or ExecutionSettings())
    result.raise_if_signalled()
    backend.trace.save(work / f"{name}.npz")
    true = evaluate_log(problem, log, work / f"{name}.npz").true
    return {
        "completed": result.completed,
        "outcome": result.reason,
        "true_mm": true.max_contour_deviation_mm,
        "true_broken": sorted({v.rule for v in true.violations}),
        "true_worst": {v.limit: [v.worst, v.allowed] for v in true.violations},
        "limit_shares": true.limit_shares,
    }


def robot_rules_unkept(predicted: PredictedCut) -> list[str]:
    """The robot's rules the predicted run breaks, or whose margin it takes (the joints'
    speed, acceleration and jerk past :data:`LIMIT_SHARES` of their limits), by name."""
    past = {f"joint {figure}" for figure in worst_by_figure(dict(predicted.past_margin))}
    return sorted({v.rule for v in predicted.broken_limits} | past)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/compensated_cut"))
    parser.add_argument("--plants", type=int, default=10)
    parser.add_argument("--flaps", default="craniotomy_bone_flap,craniotomy_five_landmarks")
    parser.add_argument("--speed-mm-s", default="4", help="comma-separated, mm/s")
    parser.add_argument("--tube-mm", type=float, default=0.12)
    parser.add_argument("--planners", default="toppra,ocp-min-jerk")
    parser.add_argument("--iterations", type=int, default=2)
    parser.add_argument("--fit-seconds", type=float, default=30.0)
    parser.add_argument("--part", default="0/1")
    parser.add_argument("--merge", action="store_true")
    args = parser.parse_args()
    if args.merge:
        rows, study = [], vars(args)
        found = sorted(args.out.glob("compensated_cut.part*.json"))
        if not found:
            parser.error(f"--merge: no compensated_cut.part*.json in {args.out}")
        for part in found:
            try:
                written = json.loads(part.read_text())
            except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
                parser.error(f"--merge: {part} is not a part's JSON ({error})")
            if not isinstance(written, dict) or written.get("rows_layout") != ROWS_LAYOUT:
                parser.error(
                    f"--merge: {part} is not a part of this version of the study (rows_layout "
                    f"{ROWS_LAYOUT}); run its part again or remove it"
                )
            rows += written["rows"]
            study = written.get("arguments", study)  # the parts' settings, not the merge's
        write_tables(argparse.Namespace(**(study | {"out": args.out})), rows)
        return
    try:
        part, parts = (int(v) for v in args.part.split("/"))
    except ValueError:
        part, parts = 0, 0
    if not 0 <= part < parts:
        parser.error(f"--part {args.part}: expected k/n, whole numbers with 0 <= k < n")
    try:
        speeds = [float(v) for v in args.speed_mm_s.split(",")]
    except ValueError:
        parser.error(f"--speed-mm-s {args.speed_mm_s}: expected comma-separated speeds, mm/s")
    args.out.mkdir(parents=True, exist_ok=True)
    flaps = {
        (name, speed): so.load_problem(
            ROOT / "problems" / f"{name}.toml",
            {"limits.max_tool_speed_mm_s": speed, "limits.contour_tolerance_mm": args.tube_mm},
        )
        for name in args.flaps.split(",")
        for speed in speeds
    }
    plans = {}
    for (name, speed), problem in flaps.items():
        for planner in args.planners.split(","):
            started = time.perf_counter()
            plans[name, speed, planner] = so.plan(problem, planner)
            progress(
                f"{name} at {speed:g} mm/s, {planner}: planned in "
                f"{time.perf_counter() - started:.1f} s"
            )
    identification = so.load_problem(IDENTIFICATION)
    fit, validation = excitation(args.fit_seconds, 0), excitation(20.0, 7)
    family, rng = PlantFamily(identification.robot), np.random.default_rng(2026)
    drawn = [family.draw(rng) for _ in range(args.plants)]
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        for index in range(part, args.plants, parts):
            plant = drawn[index]
            progress(f"plant {index + 1} of {args.plants}: identifying")
            identified = identify_plant(
                identification, plant.robot, plant.settings, fit, validation, work, IDENTIFY_RUN
            )
            robot_path = work / f"plant{index}.toml"
            robot_path.write_text(
                robot_file_text(identified.identification, identified.loops, robot_path.stem)
            )
            model = so.load_robot(robot_path)
            for (flap, speed, planner), plan in plans.items():
                problem = flaps[flap, speed]
                name = f"p{index}-{flap}-{speed:g}-{planner}"
                predicted = predict_cut(problem, plan, model)
                lead = true_run(problem, plan, plant, work, f"{name}-lead")
                started = time.perf_counter()
                compensation = compensate(problem, plan, model, iterations=args.iterations)
                compute_s = time.perf_counter() - started
                compensated = true_run(problem, compensation.plan, plant, work, f"{name}-comp")
                kept = compensation.predicted
                slowed = None
                if not kept.keeps_limits:  # slow where the joints break away, then compensate
                    started = time.perf_counter()
                    slowing = slowed_for_breakaways(problem, plan, model)
                    if slowing.feed < 1.0:
                        learned = compensate(
                            problem, slowing.trajectory, model, iterations=args.iterations
                        )
                        slowed = {
                            "feed": slowing.feed,
                            "duration_s": slowing.trajectory.duration,
                            "predicted_mm": learned.predicted.deviation_mm,
                            "predicted_inside": learned.predicted.inside,
                            "predicted_broken": robot_rules_unkept(learned.predicted),
                            "predicted_shares": learned.predicted.report.limit_shares,
                            "compute_s": time.perf_counter() - started,
                            "run": true_run(problem, learned.plan, plant, work, f"{name}-slowed"),
                            "lead_predicted_mm": slowing.predicted.deviation_mm,
                            "lead_predicted_inside": slowing.predicted.inside,
                            "lead_predicted_broken": robot_rules_unkept(slowing.predicted),
                            "lead_predicted_shares": slowing.predicted.report.limit_shares,
                            "lead_run": None,
                        }
                        if slowed["predicted_broken"] and slowing.predicted.inside:
                            slowed["lead_run"] = true_run(  # the lab's run: led, not compensated
                                problem, slowing.trajectory, plant, work, f"{name}-slowed-lead"
                            )
                slower = None
                if not kept.inside:  # the lab's next step: the lead plan at the highest feed
                    found = highest_feed_inside(problem, plan, model)
                    if found is not None:
                        feed, at_feed = found
                        run = true_run(
                            problem, plan, plant, work, f"{name}-feed", ExecutionSettings(feed=feed)
                        )
                        slower = {
                            "feed": feed,
                            "predicted_mm": at_feed.deviation_mm,
                            "predicted_broken": robot_rules_unkept(at_feed),
                            "predicted_shares": at_feed.report.limit_shares,
                            "run": run,
                        }
                row = {
                    "plant": index + 1,
                    "flap": flap,
                    "speed_mm_s": speed,
                    "planner": planner,
                    "tube_mm": contour_tube(problem, executed=True) / MM,
                    "planned_mm": so.evaluate(problem, plan).max_contour_deviation_mm,
                    "predicted_lead_mm": predicted.deviation_mm,
                    "predicted_lead_inside": predicted.inside,
                    "predicted_lead_broken": robot_rules_unkept(predicted),
                    "predicted_lead_shares": predicted.report.limit_shares,
                    "lead": lead,
                    "iterations_mm": [i.deviation_mm for i in compensation.iterations],
                    "corrections": compensation.kept,
                    "scale": compensation.plan.metadata["compensation"]["scale"],
                    "predicted_compensated_mm": kept.deviation_mm,
                    "predicted_compensated_inside": kept.inside,
                    "predicted_compensated_broken": robot_rules_unkept(kept),
                    "predicted_compensated_shares": kept.report.limit_shares,
                    "compensated": compensated,
                    "slowed": slowed,
                    "highest_feed": slower,
                    "compensation_compute_s": compute_s,
                    "plan_duration_s": plan.duration,
                    "plant_bandwidth_per_s": plant.loops()[1].tolist(),
                    "file_bandwidth_per_s": list(model.actuator.velocity_loop_bandwidth_per_s),
                }
                rows.append(row)
                progress(
                    f"  {flap} {planner}: lead predicted {row['predicted_lead_mm']:.3f}, true "
                    f"{lead['true_mm']:.3f}; compensated predicted {kept.deviation_mm:.3f}, "
                    f"true {compensated['true_mm']:.3f} mm ({compute_s:.0f} s)"
                )
    label = "-".join(f"{speed:g}" for speed in speeds)
    (args.out / f"compensated_cut.part{part}of{parts}.{label}mm_s.json").write_text(
        json.dumps(
            {
                "arguments": vars(args) | {"out": str(args.out)},
                "rows_layout": ROWS_LAYOUT,
                "rows": rows,
            },
            indent=1,
        )
    )
    if parts == 1:
        write_tables(args, rows)


def lab_run(row: dict) -> tuple[str, dict | None, float | None, list[str]]:
    """The run a lab makes after the prediction: the first predicted inside the tube and
    keeping the robot's limits with their margins, of the compensated stream, the plan
    slowed at its breakaways and compensated, and that slowed plan led alone; else the
    first of them predicted inside; else the lead plan at the highest feed predicted
    inside. Returns (which run: "compensated", "slowed", "slowed, led" or "feed", the run,
    its predicted cut (mm), the robot's rules its prediction breaks or takes the margin
    of); the run None where none was made."""
    candidates = [
        (
            "compensated",
            row["compensated"],
            row["predicted_compensated_mm"],
            row["predicted_compensated_inside"],
            row["predicted_compensated_broken"],
        )
    ]
    slowed = row["slowed"]
    if slowed is not None:
        candidates.append(
            (
                "slowed",
                slowed["run"],
                slowed["predicted_mm"],
                slowed["predicted_inside"],
                slowed["predicted_broken"],
            )
        )
        if slowed["lead_run"] is not None:
            candidates.append(
                (
                    "slowed, led",
                    slowed["lead_run"],
                    slowed["lead_predicted_mm"],
                    slowed["lead_predicted_inside"],
                    slowed["lead_predicted_broken"],
                )
            )
    for wanted in (lambda inside, unkept: inside and not unkept, lambda inside, _: inside):
        for kind, run, predicted_mm, inside, unkept in candidates:
            if wanted(inside, unkept):
                return kind, run, predicted_mm, unkept
    slower = row["highest_feed"]
    if slower is None:
        return "feed", None, None, []
    return "feed", slower["run"], slower["predicted_mm"], slower["predicted_broken"]


def limit_lines(rows: list[dict]) -> list[str]:
    """What the lab's true runs of one speed do to the robot's limits, and whether their
    predictions said so, a line each."""
    runs = [(run, predicted) for _, run, _, predicted in map(lab_run, rows) if run]
    breaking = foreseen = extra = past = 0
    for run, predicted in runs:
        broken = set(run["true_broken"]) & ROBOT_RULES
        breaking += bool(broken)
        foreseen += bool(broken) and broken <= set(predicted)
        extra += bool(set(predicted) - broken)
        past += bool(past_margin(run["limit_shares"]))
    worst = {
        figure: max(worst_by_figure(run["limit_shares"])[figure] for run, _ in runs)
        for figure in LIMIT_SHARES
    }
    shares = "; ".join(f"{figure} {share:.1%}" for figure, share in worst.items())
    return [
        f"- Robot limits on the lab's true runs: the joints' worst {shares} of the limit; "
        f"{past} of {len(runs)} past the margin the prediction keeps "
        f"({', '.join(f'{f} {v:.0%}' for f, v in LIMIT_SHARES.items())}). Of the {breaking} "
        f"that broke a robot limit, the prediction named every limit broken on {foreseen} "
        f"(as broken or as past its margin); it named a limit the true run kept on {extra} of "
        f"{len(runs)}."
    ]


class TrueRun(NamedTuple):
    """A true run of the study beside its prediction."""

    plan: str
    """The plan: "plant 1 bone_flap ocp-min-jerk"."""
    kind: str
    """Which run: "lead", "compensated", "slowed", "slowed, led" or "feed"."""
    predicted_mm: float
    """Its predicted cut's largest distance from the contour, mm."""
    predicted_shares: dict[str, float]
    """Its prediction's joint limit shares ("theta2 jerk": 0.9)."""
    run: dict
    """The true run (``true_run``'s record)."""

    @property
    def true_shares(self) -> dict[str, float]:
        """The true run's joint limit shares."""
        return self.run["limit_shares"]


def true_runs(rows: list[dict]) -> list[TrueRun]:
    """Every true run of the rows, each with its prediction."""
    made = []
    for r in rows:
        plan = f"plant {r['plant']} {r['flap'].removeprefix('craniotomy_')} {r['planner']}"
        made += [
            TrueRun(plan, "lead", r["predicted_lead_mm"], r["predicted_lead_shares"], r["lead"]),
            TrueRun(
                plan,
                "compensated",
                r["predicted_compensated_mm"],
                r["predicted_compensated_shares"],
                r["compensated"],
            ),
        ]
        slowed, slower = r["slowed"], r["highest_feed"]
        if slowed:
            made.append(
                TrueRun(
                    plan,
                    "slowed",
                    slowed["predicted_mm"],
                    slowed["predicted_shares"],
                    slowed["run"],
                )
            )
            if slowed["lead_run"]:
                made.append(
                    TrueRun(
                        plan,
                        "slowed, led",
                        slowed["lead_predicted_mm"],
                        slowed["lead_predicted_shares"],
                        slowed["lead_run"],
                    )
                )
        if slower:
            made.append(
                TrueRun(
                    plan, "feed", slower["predicted_mm"], slower["predicted_shares"], slower["run"]
                )
            )
    return made


def margin_line(rows: list[dict]) -> str:
    """How far each joint figure's true share of its limit came above its prediction's, on
    the runs predicted at :data:`MARGIN_FLOOR` of the limit or more, against the margin
    :data:`LIMIT_SHARES` keeps; one line."""
    parts, failed = [], 0
    runs = true_runs(rows)
    for figure, margin in LIMIT_SHARES.items():
        ratios = [
            (run.true_shares[name] / share, f"{run.plan}, {run.kind}")
            for run in runs
            for name, share in run.predicted_shares.items()
            if name.endswith(figure) and share >= MARGIN_FLOOR
        ]
        failed += sum(
            share <= margin < 1.0 < run.true_shares[name]
            for run in runs
            for name, share in run.predicted_shares.items()
            if name.endswith(figure)
        )
        if not ratios:
            parts.append(f"{figure}: none predicted at {MARGIN_FLOOR:.0%} or more")
            continue
        worst, where = max(ratios)
        parts.append(
            f"{figure}, margin {margin:.0%} (enough while the ratio stays under "
            f"{1 / margin:.3f}): at most {worst:.3f} ({where}), median "
            f"{np.median([v for v, _ in ratios]):.3f}, over {len(ratios)}"
        )
    return (
        f"- The margin, over {len(runs)} true runs: a joint figure's true share of its limit "
        f"over its predicted share, where the prediction reached {MARGIN_FLOOR:.0%} of the "
        f"limit or more: " + "; ".join(parts) + f". Joint figures predicted within their "
        f"margin whose true run broke the limit: {failed}."
    )


def summary_lines(rows: list[dict]) -> list[str]:
    """What the rows of one speed say, a line each."""
    runs = [lab_run(r)[:3] for r in rows]
    errors = [abs(run.predicted_mm - run.run["true_mm"]) for run in true_runs(rows)]
    inside = [
        run is not None and run["completed"] and run["true_mm"] <= r["tube_mm"]
        for r, (_, run, _) in zip(rows, runs, strict=True)
    ]
    outside = [r for r in rows if not r["predicted_compensated_inside"]]
    chosen = [kind for kind, _, _ in runs]
    broken: dict[str, int] = {}
    for _, run, _ in runs:
        for rule in run["true_broken"] if run else []:
            broken[rule] = broken.get(rule, 0) + 1
    compute = [r["compensation_compute_s"] for r in rows]
    return [
        f"- Runs: {len(rows)}; true cut inside the tube: "
        f"{sum(r['lead']['true_mm'] <= r['tube_mm'] for r in rows)} with the lead alone, "
        f"{sum(r['compensated']['true_mm'] <= r['tube_mm'] for r in rows)} compensated; "
        f"the lab's run ({chosen.count('compensated')} compensated, "
        f"{chosen.count('slowed')} slowed at the breakaways and compensated, "
        f"{chosen.count('slowed, led')} slowed and led alone, "
        f"{chosen.count('feed')} at the highest feed predicted inside): "
        f"{sum(inside)} of {len(rows)} completed inside.",
        f"- Predicted outside even compensated, before any run: {len(outside)}"
        + (
            " ("
            + "; ".join(
                f"plant {r['plant']} {r['flap'].removeprefix('craniotomy_')} {r['planner']}: "
                + (f"feed {r['highest_feed']['feed']:.2f}" if r["highest_feed"] else "no feed")
                for r in outside
            )
            + ")."
            if outside
            else "."
        ),
        _slowing_line(rows),
        f"- Prediction's error over every run (lead, compensated, slowed, slower): worst "
        f"{max(errors):.4f} mm, median {np.median(errors):.4f}; over 0.01 mm on "
        f"{sum(e > 0.01 for e in errors)} of {len(errors)}.",
        "- Rules the lab's true runs break: "
        + (", ".join(f"{rule} on {n}" for rule, n in sorted(broken.items())) or "none")
        + ".",
        *limit_lines(rows),
        margin_line(rows),
        f"- Compensation's compute: median {np.median(compute):.0f} s, at most "
        f"{max(compute):.0f} s a plan; the compensated plans are as long as their plans.",
    ]


def _with_slowed(rows: list[dict]) -> list[tuple[dict, dict]]:
    """The rows with a slowed run, each with it."""
    return [(r, r["slowed"]) for r in rows if r["slowed"]]


def _slowing_line(rows: list[dict]) -> str:
    """What slowing at the breakaways (or throughout) did to the rows of one speed, one
    line."""
    pairs = _with_slowed(rows)
    if not pairs:
        return "- Slowed at the breakaways: none."
    paces = [s["feed"] for _, s in pairs]
    true = [s["run"]["true_mm"] for _, s in pairs]
    longer = [s["duration_s"] / r["plan_duration_s"] for r, s in pairs]
    throughout = sum(
        abs(s["feed"] * x - 1.0) < 1e-6 for (_, s), x in zip(pairs, longer, strict=True)
    )
    compute = [s["compute_s"] for _, s in pairs]
    return (
        f"- Slowed at the breakaways (where the compensated stream's predicted run breaks a "
        f"robot limit or takes its margin): {len(pairs)} plans, {throughout} of them "
        f"throughout (no dip kept the limits; a uniform pace makes the plan 1/pace as "
        f"long), pace {min(paces):.2f}–{max(paces):.2f}, "
        f"{min(true):.3f}–{max(true):.3f} mm true; the plans {min(longer):.2f}–"
        f"{max(longer):.2f} times as long; slowing and compensating took median "
        f"{np.median(compute):.0f} s, at most {max(compute):.0f} s a plan."
    )


def runs_by_speed(rows: list[dict]) -> str:
    """'plants 1–10 at 4 mm/s in a 0.12 mm tube, plants 1–3 at 3 and 5 mm/s in a 0.1 mm
    tube' of the rows."""
    plants: dict[tuple[float, float], set[int]] = {}
    for r in rows:
        plants.setdefault((r["speed_mm_s"], r["tube_mm"]), set()).add(r["plant"])
    grouped: dict[tuple[str, float], list[float]] = {}
    for (speed, tube), numbers in sorted(plants.items()):
        span = f"{min(numbers)}–{max(numbers)}" if len(numbers) > 1 else f"{min(numbers)}"
        grouped.setdefault((f"plants {span}", tube), []).append(speed)
    return ", ".join(
        f"{label} at {' and '.join(f'{v:g}' for v in speeds)} mm/s in a {tube:g} mm tube"
        for (label, tube), speeds in grouped.items()
    )


def write_tables(args: argparse.Namespace, rows: list[dict]) -> None:
    """The markdown tables, the JSON and the figure of every row."""
    rows = sorted(rows, key=lambda r: (r["speed_mm_s"], r["plant"], r["flap"], r["planner"]))
    header = [
        "plant",
        "flap",
        "planner",
        "predicted (lead), mm",
        "true (lead), mm",
        "predicted (compensated), mm",
        "true (compensated), mm",
        "corrections",
        "slowed at the breakaways: pace, s, predicted / true, mm",
        "highest feed predicted inside: predicted / true, mm",
        "completed",
        "the lab's run: broken on its true run",
        "robot limits its prediction breaks or takes the margin of",
    ]

    def cells(r: dict) -> list[str]:
        slower, slowed = r["highest_feed"], r["slowed"]
        kind, run, _, predicted = lab_run(r)
        return [
            str(r["plant"]),
            r["flap"].removeprefix("craniotomy_"),
            r["planner"],
            f"{r['predicted_lead_mm']:.3f}",
            f"{r['lead']['true_mm']:.3f}",
            f"{r['predicted_compensated_mm']:.3f}",
            f"{r['compensated']['true_mm']:.3f}",
            f"{r['corrections']} (×{r['scale']:g})",
            "—"
            if slowed is None
            else f"{slowed['feed']:.2f}, {r['plan_duration_s']:.1f} → {slowed['duration_s']:.1f}: "
            f"{slowed['predicted_mm']:.3f} / {slowed['run']['true_mm']:.3f}",
            "—"
            if r["predicted_compensated_inside"]
            else (
                "none"
                if slower is None
                else f"{slower['feed']:.2f}: {slower['predicted_mm']:.3f} / "
                f"{slower['run']['true_mm']:.3f}"
            ),
            " / ".join(
                "yes" if run_["completed"] else "no"
                for run_ in (
                    r["lead"],
                    r["compensated"],
                    *([run] if kind != "compensated" and run else []),
                )
            ),
            f"{kind}: " + (", ".join(run["true_broken"]) or "none") if run else "(not run)",
            ", ".join(predicted) if run else "",
        ]

    sections = []
    for speed in sorted({r["speed_mm_s"] for r in rows}):
        chosen = [r for r in rows if r["speed_mm_s"] == speed]
        sections += [
            f"## {speed:g} mm/s, tube {chosen[0]['tube_mm']:g} mm",
            "",
            *summary_lines(chosen),
            "",
            *markdown_table(header, [cells(r) for r in chosen]),
            "",
        ]
    text = (
        "# The compensated cut on a family of plants\n\n"
        f"`python experiments/compensated_cut.py --out {args.out} --plants N "
        f"--planners {args.planners} --flaps {args.flaps} --speed-mm-s S "
        f"--tube-mm T --iterations {args.iterations} --part k/n` for each "
        f"part k of n (the runs below: {runs_by_speed(rows)}), then the same with `--merge`. "
        "Each plant identified from its own "
        f"{args.fit_seconds:g} s excitation (its velocity loops from the log's replay); the "
        "prediction and the compensation on the identified file; the true cut from the "
        "plant's true state, the plant running its own loops. Plant numbers are the family's "
        "draws from seed 2026. Where the compensated stream's predicted run breaks a robot "
        "limit or takes its margin, the plan is slowed where its joints break away "
        "(`spm-opt slow-breakaways`) and compensated again; the lab runs the first predicted "
        "inside and within the robot's limits and margins of the compensated stream, the "
        "slowed and compensated one and the slowed one led alone, else the first predicted "
        "inside. Where the "
        "compensated stream's predicted cut leaves the tube, and no slowed stream's is inside, "
        "the lab's run is the lead plan at the highest feed predicted inside "
        "(`spm-opt predict --highest-feed`). Completed: lead / compensated / the lab's run "
        "where it is neither.\n\n"
        "## Every speed\n\n"
        f"{margin_line(rows)}\n\n"
        "![Each true run's share of the joints' limits against its prediction's]"
        "(compensated_cut_limits.png)\n\n" + "\n".join(sections)
    )
    (args.out / "compensated_cut.md").write_text(text, encoding="utf-8")
    (args.out / "compensated_cut.json").write_text(json.dumps(rows, indent=1), encoding="utf-8")
    figure(rows).savefig(args.out / "compensated_cut.png", dpi=120)
    limits_figure(rows).savefig(args.out / "compensated_cut_limits.png", dpi=120)
    print(text)


def figure(rows: list[dict]) -> Figure:
    """Left: the true cut against the predicted, lead alone and compensated. Right: the
    compensated true cut against the lead alone's, by planner and flap, the tube as lines."""
    fig = Figure(figsize=(11, 5), layout="constrained")
    left, right = fig.subplots(1, 2)
    for kind, colour, marker in (("lead", "tab:orange", "o"), ("compensated", "tab:green", "s")):
        key = "predicted_lead_mm" if kind == "lead" else "predicted_compensated_mm"
        left.scatter(
            [r[key] for r in rows],
            [r[kind]["true_mm"] for r in rows],
            c=colour,
            marker=marker,
            label=kind,
        )
    others = (
        (
            [s for _, s in _with_slowed(rows)],
            "tab:red",
            "v",
            "slowed at the breakaways, compensated",
        ),
        (
            [r["highest_feed"] for r in rows if r.get("highest_feed")],
            "tab:blue",
            "^",
            "lead at the highest feed predicted inside",
        ),
        (
            [
                {"predicted_mm": s["lead_predicted_mm"], "run": s["lead_run"]}
                for _, s in _with_slowed(rows)
                if s.get("lead_run")
            ],
            "tab:purple",
            "D",
            "slowed at the breakaways, led alone",
        ),
    )
    for runs, colour, marker, label in others:
        if not runs:
            continue
        left.scatter(
            [s["predicted_mm"] for s in runs],
            [s["run"]["true_mm"] for s in runs],
            c=colour,
            marker=marker,
            label=label,
        )
    top = max(max(r["lead"]["true_mm"], r["predicted_lead_mm"]) for r in rows) * 1.1
    left.plot([0, top], [0, top], color="0.5", lw=1, label="predicted = true")
    left.plot([0, top], [0.01, top + 0.01], color="0.5", lw=1, ls=":", label="±0.01 mm")
    left.plot([0, top], [-0.01, top - 0.01], color="0.5", lw=1, ls=":")
    left.set(xlabel="predicted cut (mm)", ylabel="true cut (mm)", title="prediction")
    left.legend(loc="lower right", fontsize=8)
    colours = {"toppra": "tab:blue", "ocp-min-time": "tab:red", "ocp-min-jerk": "tab:purple"}
    markers: dict[str, str] = {}
    for r in rows:
        marker = markers.setdefault(r["flap"], "os^v"[len(markers) % 4])
        right.scatter(
            r["lead"]["true_mm"],
            r["compensated"]["true_mm"],
            c=colours.get(r["planner"], "0.3"),
            marker=marker,
        )
    for planner, colour in colours.items():
        right.scatter([], [], c=colour, label=planner)
    for flap, marker in markers.items():
        right.scatter([], [], c="0.5", marker=marker, label=flap.removeprefix("craniotomy_"))
    right.plot([0, top], [0, top], color="0.5", lw=1)
    for tube, style in zip(sorted({r["tube_mm"] for r in rows}), ("--", ":", "-."), strict=False):
        right.axhline(tube, color="k", ls=style, lw=1, label=f"tube {tube:g} mm")
        right.axvline(tube, color="k", ls=style, lw=1)
    right.set(
        xlabel="true cut, lead alone (mm)",
        ylabel="true cut, compensated (mm)",
        title="true cut: compensated against the lead alone",
    )
    right.legend(fontsize=8)
    return fig


def limits_figure(rows: list[dict]) -> Figure:
    """For the joints' speed, acceleration and jerk: each true run's share of the limit
    against its prediction's, with the limit and the margin the prediction keeps."""
    fig = Figure(figsize=(13, 4.5), layout="constrained")
    runs = true_runs(rows)
    colours = {
        "lead": "tab:orange",
        "compensated": "tab:green",
        "slowed": "tab:red",
        "slowed, led": "tab:purple",
        "feed": "tab:blue",
    }
    for axis, (figure, margin) in zip(fig.subplots(1, 3), LIMIT_SHARES.items(), strict=True):
        for kind, colour in colours.items():
            points = [
                (share, run.true_shares[name])
                for run in runs
                if run.kind == kind
                for name, share in run.predicted_shares.items()
                if name.endswith(figure)
            ]
            if points:
                x, y = np.array(points).T
                axis.scatter(100 * x, 100 * y, s=14, c=colour, label=kind)
        shares = [
            max(share, run.true_shares[name])
            for run in runs
            for name, share in run.predicted_shares.items()
            if name.endswith(figure)
        ]
        top = 100 * max(1.1, *shares)
        axis.plot([0, top], [0, top], color="0.5", lw=1, label="true = predicted")
        axis.axhline(100, color="k", lw=1, label="the limit")
        axis.axvline(100 * margin, color="k", ls="--", lw=1, label=f"margin kept ({margin:.0%})")
        axis.fill_between(
            [0, 100 * margin],
            100,
            top,
            color="tab:red",
            alpha=0.12,
            label="margin kept, limit broken",
        )
        axis.set(
            xlim=(0, top),
            ylim=(0, top),
            xlabel=f"predicted {figure}, share of the limit (%)",
            ylabel=f"true {figure}, share of the limit (%)",
            title=f"joint {figure}",
        )
        axis.legend(loc="lower right", fontsize=8)
    return fig


if __name__ == "__main__":
    sys.exit(run_script(main))
