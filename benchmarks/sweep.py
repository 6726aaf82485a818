"""Sweep throughput: tasks per second with 1 and 2 workers, per planner, in one run.

Prints a table (progress goes to stderr) and writes benchmarks/results/sweep.json.

    python benchmarks/sweep.py [--planners NAMES] [--tasks N] [--workers COUNTS]
                               [--repeats R]

NAMES are comma-separated planner names (default: cubic, toppra, ocp-min-time); COUNTS
comma-separated worker counts (default: 1,2; the first is the reference of the ratios).
Each planner's sweep is the paper's problem with ``limits.max_tool_speed_mm_s`` at N values
evenly spaced from 2 to 4 mm/s (default N = 16), each task planned and evaluated by
:func:`spm_opt.studies.sweep.task.run_task` through
:func:`spm_opt.studies.sweep.runner.run_sweep`, as ``spm-opt sweep`` does: with 1 worker in
the runner's process, with more on its process pool. Every run is a fresh Python process, so
that none inherits another's warm caches (imports, compiled functions, the optimal-control
solvers). Each planner's runs are interleaved (1, 2, 1, 2 workers...) R times (default 2)
and each column is the best of its R values: on a machine shared with other work, the least
disturbed (the JSON has them all).

- total s, tasks/s: run_sweep's wall time, with the pool's start and every worker's cold
  first task, and N over it.
- first wave s: from run_sweep's call to the W-th row with W workers: the pool's start
  (a fork server importing spm_opt), and each worker's first task with its cold caches.
- steady tasks/s: the rows after the W-th over the time from the W-th row to the last
  (the rows' ``finished_at``).
- task s: the mean of the rows' ``wall_time_s`` (planning only; the task also loads the
  problem and evaluates the plan).
- ratio, steady ratio: tasks/s and steady tasks/s over the reference worker count's,
  measured in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from timing import ROOT, write_results

import spm_opt as so
from spm_opt.studies.sweep.runner import run_sweep
from spm_opt.studies.sweep.spec import load_sweep_spec

PLANNERS = ("cubic", "toppra", "ocp-min-time")
PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"
AXIS = "limits.max_tool_speed_mm_s"
SPEEDS_MM_S = (2.0, 4.0)


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def write_spec(directory: Path, planner: str, count: int) -> Path:
    """A sweep of ``count`` tool-speed limits for ``planner`` on the paper's problem."""
    values = [round(float(v), 4) for v in np.linspace(*SPEEDS_MM_S, count)]
    path = directory / f"{planner}.toml"
    path.write_text(
        f'name = "benchmark-{planner}"\n'
        f"problem = {json.dumps(str(PROBLEM))}\n"
        f"planners = [{json.dumps(planner)}]\n"
        f"[grid]\n{json.dumps(AXIS)} = {json.dumps(values)}\n"
    )
    return path


def measure(spec: Path, workers: int, out: Path) -> dict[str, Any]:
    """Run the sweep (in this process: the child's side) and time it from its rows."""
    tasks = load_sweep_spec(spec).tasks()
    started = datetime.now(UTC)
    summary = run_sweep(tasks, out, workers=workers, progress=False)
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    ends = sorted(
        (datetime.fromisoformat(r["finished_at"]) - started).total_seconds() for r in rows
    )
    wave = ends[min(workers, len(ends)) - 1]
    steady = (len(ends) - workers) / (ends[-1] - wave) if len(ends) > workers else None
    times = [r["wall_time_s"] for r in rows if r.get("wall_time_s") is not None]
    return {
        "tasks": summary.total,
        "failed": summary.failed,
        "seconds": summary.seconds,
        "tasks_per_s": summary.total / summary.seconds,
        "first_wave_s": wave,
        "steady_tasks_per_s": steady,
        "mean_task_wall_s": float(np.mean(times)) if times else None,
        "workers_seen": len({r.get("worker") for r in rows}),
        "statuses": dict(Counter(r["status"] for r in rows)),
    }


def run_child(spec: Path, workers: int, out: Path) -> dict[str, Any]:
    """:func:`measure` in a fresh Python process."""
    command = [sys.executable, __file__, "--child", str(spec), str(workers), str(out)]
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    return json.loads(done.stdout.splitlines()[-1])


def best(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Each timing's best over the runs, and every run."""

    def extreme(name: str, pick: Any) -> float | None:
        values = [r[name] for r in runs if r[name] is not None]
        return pick(values) if values else None

    return {
        **runs[0],
        "seconds": extreme("seconds", min),
        "tasks_per_s": extreme("tasks_per_s", max),
        "first_wave_s": extreme("first_wave_s", min),
        "steady_tasks_per_s": extreme("steady_tasks_per_s", max),
        "mean_task_wall_s": extreme("mean_task_wall_s", min),
        "runs": runs,
    }


def number(value: float | None, width: int, digits: str = ".3g") -> str:
    return f"{'-':>{width}s}" if value is None else f"{value:{width}{digits}}"


def print_table(results: dict[str, dict[str, dict[str, Any]]]) -> None:
    print(
        f"{'planner':14s} {'workers':>7s} {'tasks':>5s} {'total s':>8s} {'tasks/s':>8s} "
        f"{'first wave s':>12s} {'steady tasks/s':>14s} {'task s':>7s} {'ratio':>6s} "
        f"{'steady ratio':>12s}"
    )
    for planner, runs in results.items():
        for workers, r in runs.items():
            ratio = r.get("ratio")
            steady_ratio = r.get("steady_ratio")
            print(
                f"{planner:14s} {workers:>7s} {r['tasks']:5d} {r['seconds']:8.2f} "
                f"{r['tasks_per_s']:8.3g} {r['first_wave_s']:12.2f} "
                f"{number(r['steady_tasks_per_s'], 14)} {number(r['mean_task_wall_s'], 7)} "
                f"{'-' if ratio is None else f'{ratio:.2f}x':>6s} "
                f"{'-' if steady_ratio is None else f'{steady_ratio:.2f}x':>12s}"
            )


def counts_option(parser: argparse.ArgumentParser, text: str) -> list[int]:
    try:
        counts = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        parser.error(f"--workers {text!r}: expected comma-separated whole numbers like 1,2")
    if not counts or min(counts) < 1:
        parser.error(f"--workers {text!r}: expected worker counts of at least 1")
    return list(dict.fromkeys(counts))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default=",".join(PLANNERS), help="comma-separated names")
    parser.add_argument("--tasks", type=int, default=16, help="tasks per sweep (tool speeds)")
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    parser.add_argument("--repeats", type=int, default=2, help="runs per row, best kept")
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        spec, workers, out = args.child
        print(json.dumps(measure(Path(spec), int(workers), Path(out))))
        return
    planners = [name.strip() for name in args.planners.split(",") if name.strip()]
    unknown = [name for name in planners if name not in so.PLANNERS]
    if unknown or not planners:
        parser.error(f"--planners {args.planners!r}: expected some of {', '.join(so.PLANNERS)}")
    if args.tasks < 2:
        parser.error("--tasks must be at least 2")
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    counts = counts_option(parser, args.workers)

    load_before = os.getloadavg()
    results: dict[str, dict[str, dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory() as scratch:
        for planner in planners:
            spec = write_spec(Path(scratch), planner, args.tasks)
            every: dict[int, list[dict[str, Any]]] = {workers: [] for workers in counts}
            for repeat in range(args.repeats):
                for workers in counts:
                    progress(f"{planner}: {args.tasks} tasks on {workers} worker(s) ...")
                    started = time.perf_counter()
                    out = Path(scratch) / f"{planner}-{workers}-{repeat}"
                    every[workers].append(run_child(spec, workers, out))
                    progress(f"{planner}: {time.perf_counter() - started:.1f} s")
            runs = results[planner] = {str(w): best(every[w]) for w in counts}
            reference = runs[str(counts[0])]
            for r in runs.values():
                r["ratio"] = r["tasks_per_s"] / reference["tasks_per_s"]
                if r["steady_tasks_per_s"] and reference["steady_tasks_per_s"]:
                    r["steady_ratio"] = r["steady_tasks_per_s"] / reference["steady_tasks_per_s"]
    load_after = os.getloadavg()

    print(
        f"problem {PROBLEM.relative_to(ROOT)}, {AXIS} at {args.tasks} values in "
        f"[{SPEEDS_MM_S[0]:g}, {SPEEDS_MM_S[1]:g}] mm/s; a fresh process per run; "
        f"best of {args.repeats} runs per column"
    )
    print_table(results)
    print(f"(ratios: against {counts[0]} worker(s), measured in the same run)")
    for planner in planners:
        if planner.startswith("ocp-"):
            for workers, r in results[planner].items():
                steady = r["steady_tasks_per_s"]
                print(
                    f"{planner} on {workers} worker(s): {60 * r['tasks_per_s']:.0f} tasks/min, "
                    f"{'-' if steady is None else f'{60 * steady:.0f}'} tasks/min steady"
                )
    print(
        f"load average (1/5/15 min) {' '.join(f'{v:.2f}' for v in load_before)} before, "
        f"{' '.join(f'{v:.2f}' for v in load_after)} after, on {os.cpu_count()} CPUs"
    )
    write_results(
        "sweep",
        {
            "cpus": os.cpu_count(),
            "load_average_before": load_before,
            "load_average_after": load_after,
            "spm_opt": so.__version__,
            "problem": str(PROBLEM.relative_to(ROOT)),
            "axis": AXIS,
            "values": args.tasks,
            "range": list(SPEEDS_MM_S),
            "repeats": args.repeats,
            "reference_workers": counts[0],
            "results": results,
        },
    )


if __name__ == "__main__":
    main()
