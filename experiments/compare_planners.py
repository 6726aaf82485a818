"""Compare the planners on every problem in problems/ and write one combined table.

For each problem file: the comparison's table and figures in OUT/<problem name>/ (as
``spm-opt compare`` writes them); then OUT/all_problems.csv and OUT/all_problems.md with
every planner on every problem, one row each.

    python experiments/compare_planners.py [--planners NAMES] [--out DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

import spm_opt as so
from spm_opt.comparison import (
    comparison_table,
    print_progress,
    run_planners,
    write_comparison,
)
from spm_opt.files import write_atomically

ROOT = Path(__file__).resolve().parents[1]
SHOWN = [
    "problem",
    "planner",
    "status",
    "wall_time_s",
    "duration_s",
    "duration_over_lower_bound",
    "max_contour_deviation_mm",
    "max_tool_speed_mm_s",
    "effort_n2m2s",
    "rms_jerk_1_rad_s3",
    "rms_jerk_2_rad_s3",
]


def markdown_table(frame: pd.DataFrame) -> str:
    """A DataFrame as a markdown table, numbers to four significant digits."""

    def cell(value: object) -> str:
        return f"{value:.4g}" if isinstance(value, float) else str(value)

    lines = ["| " + " | ".join(frame.columns) + " |", "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(False)]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default=None, help="comma-separated names (default: all)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "all_problems")
    args = parser.parse_args()
    names = None if args.planners is None else args.planners.split(",")
    tables = []
    for path in sorted((ROOT / "problems").glob("*.toml")):
        problem = so.load_problem(path)
        outcomes = run_planners(problem, names, print_progress(f"{problem.name} "))
        write_comparison(problem, outcomes, args.out / problem.name)
        tables.append(comparison_table(outcomes).assign(problem=problem.name))
    combined = pd.concat(tables, ignore_index=True)
    combined = combined[["problem", *[c for c in combined.columns if c != "problem"]]]
    write_atomically(
        {
            args.out / "all_problems.csv": combined.to_csv(index=False),
            args.out / "all_problems.md": "# Every planner on every problem\n\n"
            + markdown_table(combined[SHOWN]),
        }
    )
    print(args.out / "all_problems.md")


if __name__ == "__main__":
    main()
