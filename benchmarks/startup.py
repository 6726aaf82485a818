"""The command line's start-up: ``spm-opt --help``, ``--version`` and ``CMD --help``.

Each command runs in a fresh Python process (``python -c`` calling ``spm_opt.cli.main``
on this checkout), several times; the table gives the best and median wall-clock times
and, as the reference measured in the same run, a bare interpreter's start-up
(``python -c pass``). Prints a table and writes benchmarks/results/startup.json.

    python benchmarks/startup.py [--repeats 7]

For what a command imports: ``python -X importtime -c "from spm_opt.cli import main;
main(['--help'])"``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from timing import ROOT, write_results

CLI = "import sys; from spm_opt.cli import main; sys.exit(main())"
COMMANDS = {
    "python -c pass (reference)": None,
    "spm-opt --help": ["--help"],
    "spm-opt --version": ["--version"],
    "spm-opt plan --help": ["plan", "--help"],
    "spm-opt compare --help": ["compare", "--help"],
    "spm-opt execute --help": ["execute", "--help"],
    "spm-opt sweep --help": ["sweep", "--help"],
    "spm-opt reproduce --help": ["reproduce", "--help"],
}
"""Each timed row: the arguments given to ``spm-opt`` (None: the bare interpreter)."""


def _times(arguments: list[str] | None, repeats: int) -> list[float]:
    """Wall-clock times of ``repeats`` fresh processes, s; each must exit with status 0."""
    command = [sys.executable, "-c", "pass" if arguments is None else CLI, *(arguments or [])]
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(command, cwd=ROOT, env=environment, check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="processes per command")
    args = parser.parse_args()

    rows = {}
    for label, arguments in COMMANDS.items():
        print(f"{label} ...", file=sys.stderr)
        times = _times(arguments, args.repeats)
        rows[label] = {"best_s": min(times), "median_s": statistics.median(times), "times_s": times}
    print(f"{'command':28s} {'best s':>8s} {'median s':>9s}")
    for label, r in rows.items():
        print(f"{label:28s} {r['best_s']:8.3f} {r['median_s']:9.3f}")
    print(f"({args.repeats} fresh processes each; the CPUs' load: {os.getloadavg()[0]:.2f})")
    write_results("startup", {"repeats": args.repeats, "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
