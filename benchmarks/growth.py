"""How plan + judge time grows with the flap: regular polygons of 4, 6, 8 and 12 landmarks.

Prints a table (progress goes to stderr) and writes benchmarks/results/growth.json.

    python benchmarks/growth.py [--landmarks 4,6,8,12] [--planners NAMES] [--repeats R]

Every flap is the paper's problem (robot, limits, planner settings) cutting a regular
polygon of one size: its landmarks on the sphere through the paper's landmarks' mean radius
(from the isocenter), at the paper's landmarks' mean angular distance from their centre,
at even azimuths counterclockwise seen from outside the skull, with segment durations of
the sweeps' mean tool speed (two thirds of the tool-speed limit; the bound of
``ocp-min-energy`` and the total of ``ocp-min-jerk``). Per flap and planner: one cold plan
(not timed: it pays for the NLP's construction), then ``--repeats`` warm ``spm_opt.plan``
followed by ``spm_opt.judge.evaluate`` of the returned plan, as a user judges it; the table has
their median wall time, the median solver iterations (ocp-* planners: IPOPT's or FATROP's)
and the plan's duration. The last columns are each planner's median time per segment
against the first flap's: growth no faster than linear in the segments keeps that ratio
near or below 1.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from statistics import median
from typing import Any

import numpy as np
from timing import ROOT, write_results

import spm_opt as so
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem
from spm_opt.studies.sweep.flaps import DURATION_SPEED_FRACTION

PAPER = ROOT / "problems" / "craniotomy_bone_flap.toml"
DEFAULT_PLANNERS = ("toppra", "ocp-min-time", "ocp-min-energy", "ocp-min-jerk", "ocp-mix")


def regular_flap(base: Problem, landmarks: int) -> Problem:
    """``base`` cutting a regular ``landmarks``-gon of the size of its own landmarks."""
    points = np.asarray(base.landmarks, dtype=float)
    radius = float(np.mean(np.linalg.norm(points, axis=1)))
    directions = points / np.linalg.norm(points, axis=1, keepdims=True)
    centre = np.mean(directions, axis=0)
    centre /= np.linalg.norm(centre)
    spread = float(np.mean(np.arccos(np.clip(directions @ centre, -1.0, 1.0))))
    first = directions[0] - (directions[0] @ centre) * centre
    first /= np.linalg.norm(first)
    second = np.cross(centre, first)  # counterclockwise seen from outside
    azimuths = 2 * np.pi * np.arange(landmarks) / landmarks
    ring = np.cos(azimuths)[:, None] * first + np.sin(azimuths)[:, None] * second
    flap = radius * (np.cos(spread) * centre + np.sin(spread) * ring)
    speed = DURATION_SPEED_FRACTION * base.limits.max_tool_speed
    chords = np.linalg.norm(np.roll(flap, -1, axis=0) - flap, axis=1)
    arcs = 2 * radius * np.arcsin(chords / (2 * radius))
    return dataclasses.replace(
        base,
        name=f"regular_{landmarks}_gon",
        description=f"A regular {landmarks}-landmark flap",
        landmark_names=tuple(f"P{k + 1}" for k in range(landmarks)),
        landmarks=flap,
        closed=True,
        segment_durations=arcs / speed,
        source=None,
        source_sha256=None,
    )


def _timed(problem: Problem, planner: str, repeats: int) -> dict[str, Any]:
    """Median plan + judge wall time, iterations and duration of warm plans."""
    so.plan(problem, planner)
    times, iterations = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        plan = so.plan(problem, planner)
        so.evaluate(problem, plan)
        times.append(time.perf_counter() - start)
        iterations.append(plan.metadata.get("statistics", {}).get("iterations"))
    counted = [i for i in iterations if i is not None]
    return {
        "plan_and_judge_s": median(times),
        "iterations": median(counted) if counted else None,
        "duration_s": plan.duration,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--landmarks", default="4,6,8,12")
    parser.add_argument("--planners", default=",".join(DEFAULT_PLANNERS))
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    counts = [int(n) for n in args.landmarks.split(",")]
    planners = args.planners.split(",")
    base = so.load_problem(PAPER)
    results: dict[str, dict[str, Any]] = {}
    for count in counts:
        problem = regular_flap(base, count)
        for planner in planners:
            print(f"{count} landmarks, {planner} ...", file=sys.stderr, flush=True)
            try:
                results[f"{count}/{planner}"] = _timed(problem, planner, args.repeats)
            except so.PlanningError as error:
                results[f"{count}/{planner}"] = {"error": str(error)}
    _print_table(counts, planners, results)
    speed = base.limits.max_tool_speed / MM
    print(
        f"tool speed limit {speed:.2f} mm/s, segments at {DURATION_SPEED_FRACTION * speed:.2f} mm/s"
    )
    write_results(
        "growth",
        {"repeats": args.repeats, "landmarks": counts, "planners": planners, "results": results},
    )


def _print_table(counts: list[int], planners: list[str], results: dict[str, Any]) -> None:
    """One row per flap: each planner's median plan + judge s, iterations and duration."""
    print(f"{'landmarks':>9s} " + " ".join(f"{p:>30s}" for p in planners))
    first = {p: results[f"{counts[0]}/{p}"].get("plan_and_judge_s") for p in planners}
    for count in counts:
        cells = []
        for planner in planners:
            row = results[f"{count}/{planner}"]
            if "error" in row:
                cells.append(f"{'failed':>30s}")
                continue
            iterations = "" if row["iterations"] is None else f", {row['iterations']:.0f} it"
            per_segment = row["plan_and_judge_s"] / count
            growth = per_segment / (first[planner] / counts[0]) if first[planner] else float("nan")
            row["per_segment_ratio"] = growth
            time_s, duration = row["plan_and_judge_s"], row["duration_s"]
            text = f"{time_s:.3f} s{iterations}, {duration:.2f} s ×{growth:.2f}"
            cells.append(f"{text:>30s}")
        print(f"{count:9d} " + " ".join(cells))
    print(
        "(median wall time of plan + evaluate of warm plans, the plan's solver iterations and"
        " duration, and ×: time per segment against the first row's)"
    )


if __name__ == "__main__":
    main()
