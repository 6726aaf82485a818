"""Compare the planners on every problem in problems/ and write one combined table.

For each problem file: the comparison's table and figures in OUT/<problem name>/ (as
``spm-opt compare`` writes them); then OUT/all_problems.csv and OUT/all_problems.md with
every planner on every problem, one row each.

    python experiments/compare_planners.py [--planners NAMES] [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import pandas as pd

import spm_opt as so
from spm_opt.base.files import write_atomically
from spm_opt.base.markdown import markdown_table
from spm_opt.cli.run import run_script
from spm_opt.report.columns import column
from spm_opt.studies.comparison import (
    comparison_table,
    progress_line,
    run_planners,
    write_comparison,
)

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


def combined_markdown(frame: pd.DataFrame) -> str:
    """The combined table's :data:`SHOWN` columns in markdown, under their headings."""
    headings = [name if name == "problem" else column(name).heading for name in SHOWN]
    rows = [
        [value if name == "problem" else column(name).show(value) for name, value in row.items()]
        for row in frame[SHOWN].to_dict("records")
    ]
    return "\n".join(markdown_table(headings, rows)) + "\n"


def progress(prefix: str) -> Callable[..., None]:
    """A progress callback that prints each planner's start and result to stderr."""
    return lambda *call: print(prefix + progress_line(*call), file=sys.stderr, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default=None, help="comma-separated names (default: all)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "all_problems")
    args = parser.parse_args()
    names = None if args.planners is None else args.planners.split(",")
    tables = []
    for path in sorted((ROOT / "problems").glob("*.toml")):
        problem = so.load_problem(path)
        outcomes = run_planners(problem, names, progress(f"{problem.name} "))
        write_comparison(problem, outcomes, args.out / problem.name)
        tables.append(comparison_table(outcomes).assign(problem=problem.name))
    combined = pd.concat(tables, ignore_index=True)
    combined = combined[["problem", *[c for c in combined.columns if c != "problem"]]]
    write_atomically(
        {
            args.out / "all_problems.csv": combined.to_csv(index=False),
            args.out / "all_problems.md": "# Every planner on every problem\n\n"
            + combined_markdown(combined),
        }
    )
    print(args.out / "all_problems.md")


if __name__ == "__main__":
    sys.exit(run_script(main))
