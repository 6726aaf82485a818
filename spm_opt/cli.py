"""The ``spm-opt`` command line, thin over the library.

A user's mistake prints one line, ``spm-opt: error: ...``, and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from spm_opt.errors import InputError, SpmOptError

PAPER_PROBLEM = "problems/craniotomy_bone_flap.toml"


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line and status 2 like every other error."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"spm-opt: error: {message} (see {self.prog} --help)\n")


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="spm-opt", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    reproduce = commands.add_parser("reproduce", help="reproduce the paper's Table III and Fig. 8")
    reproduce.add_argument("--out", required=True, type=Path, help="output directory")
    reproduce.add_argument(
        "--problem",
        default=PAPER_PROBLEM,
        type=Path,
        help=f"the paper's problem file (default: {PAPER_PROBLEM})",
    )

    plan = commands.add_parser("plan", help="plan a problem and write the trajectory CSV")
    plan.add_argument("problem", type=Path, help="problem TOML file")
    plan.add_argument("--planner", default="cubic", help="planner name (default: cubic)")
    plan.add_argument("--out", required=True, type=Path, help="trajectory CSV to write")
    plan.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help="sampling rate of the CSV (default 100 Hz, breakpoints included)",
    )

    compare = commands.add_parser(
        "compare", help="run every planner on a problem and compare them (table and figures)"
    )
    compare.add_argument("problem", type=Path, help="problem TOML file")
    compare.add_argument(
        "--planners",
        default=None,
        metavar="NAMES",
        help="comma-separated planner names (default: every registered planner)",
    )
    compare.add_argument("--out", required=True, type=Path, help="output directory")

    evaluate = commands.add_parser("evaluate", help="measure a trajectory CSV against a problem")
    evaluate.add_argument("problem", type=Path, help="problem TOML file")
    evaluate.add_argument("trajectory", type=Path, help="trajectory CSV file")
    evaluate.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def _reproduce(args: argparse.Namespace) -> None:
    from spm_opt.reproduce import reproduce

    if not args.problem.is_file():
        raise InputError(
            f"--problem {args.problem}: no such file (run from the repository's root, or "
            "pass --problem with the path of craniotomy_bone_flap.toml)"
        )
    for path in reproduce(args.problem, args.out):
        print(path)


def _plan(args: argparse.Namespace) -> None:
    from spm_opt.planners import get_planner, plan
    from spm_opt.problem import load_problem

    if args.out.suffix != ".csv":
        raise InputError(f"--out {args.out}: expected a file name ending in .csv")
    if args.rate is not None and not 0.0 < args.rate <= 1e5:
        raise InputError(f"--rate {args.rate}: expected a rate in Hz with 0 < rate <= 100000")
    get_planner(args.planner)
    problem = load_problem(args.problem)
    trajectory = plan(problem, args.planner)
    trajectory.to_csv(args.out, rate_hz=args.rate)
    print(f"{args.out}: {args.planner} plan, {trajectory.duration:.3f} s")


def _evaluate(args: argparse.Namespace) -> None:
    from spm_opt.evaluate import evaluate
    from spm_opt.problem import load_problem
    from spm_opt.trajectory import Trajectory

    problem = load_problem(args.problem)
    report = evaluate(problem, Trajectory.from_csv(args.trajectory))
    print(json.dumps(report.to_dict(), indent=2) if args.json else report.to_markdown(), end="")


def _compare(args: argparse.Namespace) -> None:
    from spm_opt.comparison import print_progress, run_planners, write_comparison
    from spm_opt.problem import load_problem

    names = None
    if args.planners is not None:
        names = [name.strip() for name in args.planners.split(",") if name.strip()]
        if not names:
            raise InputError(f"--planners {args.planners!r}: expected comma-separated names")
    problem = load_problem(args.problem)
    outcomes = run_planners(problem, names, print_progress())
    for path in write_comparison(problem, outcomes, args.out):
        print(path)


_COMMANDS = {
    "reproduce": _reproduce,
    "plan": _plan,
    "compare": _compare,
    "evaluate": _evaluate,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = _parser().parse_args(argv)
    try:
        _COMMANDS[args.command](args)
    except SpmOptError as error:
        print(f"spm-opt: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:  # an output path that cannot be written: the user can fix it
        where = f"{error.filename}: " if error.filename else ""
        print(f"spm-opt: error: {where}cannot write ({error.strerror or error})", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("spm-opt: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
