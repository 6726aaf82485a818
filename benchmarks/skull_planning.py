"""Planning on a skull mesh against the same flap without one, in one run.

Prints a table (progress goes to stderr) and writes benchmarks/results/skull_planning.json.

    python benchmarks/skull_planning.py [--subdivisions 6] [--repeats 5] [--planners NAMES]

A skull is generated (``spm_opt.skull.example_problem``: an icosphere subdivided
``--subdivisions`` times, 6 giving 81,920 triangles a surface and 7 giving 327,680) with the
example's flap and problem file, in a temporary folder. Two problems are loaded from it:
"mesh", the problem file as written (the flap planned on the outer mesh: ray casts and the
arcs' radius fits), and "landmarks", the same landmarks (moved onto the mesh) given as
``[[landmarks]]`` without a ``[skull]`` table or the bone's thickness limit (the smooth
surface through them). Per planner and problem: the load time, the first plan (with the
problem's lazily computed contour, fits and bounds) and the median of ``--repeats`` warm
plans (the planners judge their own plans inside as usual); then the
median of ``--repeats`` evaluations of the plan alone, each of a fresh copy (the evaluator
keeps a plan's last report). The ratio is mesh over landmarks, measured in the same run.
"""

from __future__ import annotations

import argparse
import copy
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

from timing import ROOT, write_results

import spm_opt as so
from spm_opt.skull.example_problem import write_example_problem


def _timed(work):  # noqa: ANN001, ANN202
    start = time.perf_counter()
    value = work()
    return time.perf_counter() - start, value


def _landmark_copy(problem_path: Path, problem: so.Problem) -> Path:
    """The problem file with the mesh's landmarks as [[landmarks]] and no [skull] table."""
    import tomllib

    import tomli_w

    data = tomllib.loads(problem_path.read_text())
    data.pop("skull", None)
    data.pop("landmarks_file", None)
    data["limits"].pop("min_bone_thickness_mm", None)  # measured on the inner mesh only
    data["landmarks"] = [
        {"name": name, "position_mm": (point * 1e3).tolist()}
        for name, point in zip(problem.landmark_names, problem.landmarks, strict=True)
    ]
    data["closed"] = problem.closed
    landmarks_only = problem_path.with_name("landmarks_only.toml")
    landmarks_only.write_text(tomli_w.dumps(data))
    return landmarks_only


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--planners", default="toppra,ocp-min-time,ocp-min-energy,ocp-min-jerk")
    args = parser.parse_args()
    planners = args.planners.split(",")
    with tempfile.TemporaryDirectory() as folder:
        robot = ROOT / "problems" / "robots" / "prototype.toml"
        mesh_path = write_example_problem(
            Path(folder) / "skull_flap.toml", subdivisions=args.subdivisions, robot=str(robot)
        )
        mesh_problem = so.load_problem(mesh_path)
        faces = len(mesh_problem.skull.outer_mesh.faces)
        paths = {"mesh": mesh_path, "landmarks": _landmark_copy(mesh_path, mesh_problem)}
        rows = []
        for planner in planners:
            for surface, path in paths.items():
                print(f"{planner} on the {surface} surface ...", file=sys.stderr)
                load_s, problem = _timed(lambda p=path: so.load_problem(p))
                first_s, plan = _timed(lambda p=problem, n=planner: so.plan(p, n))
                warm = [
                    _timed(lambda p=problem, n=planner: so.plan(p, n))[0]
                    for _ in range(args.repeats)
                ]
                copies = [copy.deepcopy(plan) for _ in range(args.repeats)]  # not yet judged
                judge = [_timed(lambda p=problem, t=t: so.evaluate(p, t))[0] for t in copies]
                report = so.evaluate(problem, plan)
                rows.append(
                    {
                        "planner": planner,
                        "surface": surface,
                        "load_s": load_s,
                        "first_s": first_s,
                        "median_s": median(warm),
                        "judge_s": median(judge),
                        "duration_s": plan.duration,
                        "violations": len(report.violations),
                    }
                )
    print(f"skull mesh: {faces:,} triangles; medians of {args.repeats} warm plans")
    header = f"{'planner':16s} {'surface':10s} {'load s':>7s} {'first s':>8s} {'median s':>9s}"
    print(header + f" {'judge s':>8s} {'duration s':>10s} {'viol.':>5s} {'ratio':>6s}")
    by_key = {(r["planner"], r["surface"]): r for r in rows}
    for row in rows:
        row["ratio_to_landmarks"] = (
            row["median_s"] / by_key[(row["planner"], "landmarks")]["median_s"]
        )
        print(
            f"{row['planner']:16s} {row['surface']:10s} {row['load_s']:7.2f} "
            f"{row['first_s']:8.2f} {row['median_s']:9.3f} {row['judge_s']:8.3f} "
            f"{row['duration_s']:10.2f} {row['violations']:5d} {row['ratio_to_landmarks']:5.2f}x"
        )
    print("(ratio: the median plan on the mesh over the same flap without it, this run)")
    write_results("skull_planning", {"faces": faces, "repeats": args.repeats, "rows": rows})


if __name__ == "__main__":
    main()
