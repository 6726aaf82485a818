"""Reproduce the paper's tables and figures through the library (what ``spm-opt reproduce``
writes): Tables III and IV, Figs. 8, 13 and 14 and the baseline's evaluation.

    python experiments/reproduce_paper.py [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spm_opt.cli.run import run_script
from spm_opt.studies.reproduce import reproduce

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "paper")
    args = parser.parse_args()
    for path in reproduce(ROOT / "problems" / "craniotomy_bone_flap.toml", args.out):
        print(path)


if __name__ == "__main__":
    sys.exit(run_script(main))
