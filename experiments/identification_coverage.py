"""How honest identification's standard errors are, on plants whose truth is known.

Two sweeps on the simulated robot, each plant identified from its own excitation log
(``problems/identification.toml``'s excitation, shortened) and checked on a validation
excitation of another seed:

- **the plant equal to the model** (prototype.toml), over ``--seeds`` excitation seeds,
  each with its own current noise: how many truths lie within two standard errors;
- **a family of plants** around it (``--plants``, :mod:`spm_opt.verify.plant_family`):
  the same coverage, the identified robot's validation torques against the prior's, and
  how often the plant's own model predicts its torques within the noise.

    python experiments/identification_coverage.py [--seeds 20] [--plants 50]
        [--fit-seconds 60] [--out DIR]

writes DIR/coverage.md and DIR/coverage.json (default results/identification_coverage),
and prints the table; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

import spm_opt as so
from spm_opt.base.markdown import markdown_table
from spm_opt.cli.run import run_script
from spm_opt.execution import ExecutionSettings
from spm_opt.execution.plant import PlantSettings
from spm_opt.studies.identified_plants import (
    NOISE_ROOM,
    PlantIdentification,
    coverage,
    identify_plant,
)
from spm_opt.verify.plant_family import PlantFamily

ROOT = Path(__file__).resolve().parents[1]
PROBLEM = ROOT / "problems" / "identification.toml"
RUN = ExecutionSettings(
    rate_hz=100.0, current_reads_per_cycle=10, max_following_error_rad=np.radians(5.0)
)
"""100 Hz, ten current reads a period (the simulated robot's default on the command line),
a following error of up to 5° (the plants' loops differ from the prior's the lead uses)."""


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def excitation(seconds: float, seed: int) -> so.Trajectory:
    """The problem's excitation of about ``seconds`` in periods of 10 s, designed from
    ``seed`` (its design stopped after 60 IPOPT iterations)."""
    options = {
        "duration_s": 10.0 * max(1, round(seconds / 10.0)),
        "periods": max(1, round(seconds / 10.0)),
        "seed": seed,
        "max_iterations": 60,
    }
    return so.plan(so.load_problem(PROBLEM, {"planner.excitation": options}), "excitation")


def summary(label: str, results: list[PlantIdentification]) -> dict[str, object]:
    """One row of the table: coverage of all and of identified parameters, the worst
    prediction gain, how often the model holds."""
    within_all, all_counted = coverage(results, identified_only=False)
    within, counted = coverage(results, identified_only=True)
    holding = [r for r in results if r.model_holds()]
    held_within, held_counted = coverage(holding, identified_only=True)
    gains = np.array([r.prediction_gain() for r in results])
    noise_limited = np.array([r.prior_rms <= NOISE_ROOM * r.plant_rms for r in results])
    viscous = [
        r.identification.unconstrained[k] - r.truth[k]
        for r in results
        for k in (r.identification.names.index(f"viscous_friction.theta{j}") for j in (1, 2))
    ]
    outside_noise = gains[~noise_limited]
    worst = float(np.min(outside_noise)) if outside_noise.size else None
    return {
        "sweep": label,
        "plants": len(results),
        "coverage_all": within_all / all_counted,
        "coverage_identified": within / counted if counted else None,
        "identified": counted,
        "model_holds": len(holding),
        "coverage_identified_where_model_holds": held_within / held_counted
        if held_counted
        else None,
        "worst_prediction_gain": worst,
        "median_prediction_gain": float(np.median(gains)),
        "viscous_error_max_nm_s_rad": float(np.max(np.abs(viscous))),
        "plant_rms_median_nm": float(np.median([r.plant_rms for r in results])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--plants", type=int, default=50)
    parser.add_argument("--fit-seconds", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=Path("results/identification_coverage"))
    args = parser.parse_args()
    problem = so.load_problem(PROBLEM)
    validation = excitation(20.0, seed=7)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        model = []
        for seed in range(args.seeds):
            progress(f"plant equal to the model, excitation seed {seed}")
            plan = excitation(args.fit_seconds, seed)
            model.append(
                identify_plant(
                    problem,
                    problem.robot,
                    PlantSettings(seed=seed),
                    plan,
                    validation,
                    Path(folder),
                    RUN,
                )
            )
        if model:
            rows.append(summary("plant equal to the model", model))
        family, rng = PlantFamily(problem.robot), np.random.default_rng(2026)
        plan = excitation(args.fit_seconds, 0)
        plants = []
        for index in range(args.plants):
            progress(f"family plant {index + 1} of {args.plants}")
            plant = family.draw(rng)
            plants.append(
                identify_plant(
                    problem, plant.robot, plant.settings, plan, validation, Path(folder), RUN
                )
            )
        if plants:
            rows.append(summary("family around prototype.toml", plants))
    args.out.mkdir(parents=True, exist_ok=True)
    header = [
        "sweep",
        "plants",
        "truths within 2 s.e. (all)",
        "(identified)",
        "identified",
        "model within the noise",
        "(identified, there)",
        "worst gain",
        "median gain",
        "largest viscous error, N·m·s/rad",
    ]
    table = markdown_table(
        header,
        [
            [
                row["sweep"],
                str(row["plants"]),
                f"{row['coverage_all']:.1%}",
                "" if row["coverage_identified"] is None else f"{row['coverage_identified']:.1%}",
                str(row["identified"]),
                str(row["model_holds"]),
                ""
                if row["coverage_identified_where_model_holds"] is None
                else f"{row['coverage_identified_where_model_holds']:.1%}",
                ""
                if row["worst_prediction_gain"] is None
                else f"{row['worst_prediction_gain']:.3g}",
                f"{row['median_prediction_gain']:.3g}",
                f"{row['viscous_error_max_nm_s_rad']:.4f}",
            ]
            for row in rows
        ],
    )
    command = (
        f"python experiments/identification_coverage.py --seeds {args.seeds} "
        f"--plants {args.plants} --fit-seconds {args.fit_seconds:g}"
    )
    text = (
        "# Identification's coverage on plants of known truth\n\n"
        f"`{command}`: {args.fit_seconds:g} s of excitation at 100 Hz with ten current reads a "
        "period, a 20 s validation excitation of another seed. Gains are the prior's "
        "validation RMS over the identified robot's (the worst leaves out plants whose prior "
        "already predicts within 1.5 times the plant's own model).\n\n" + "\n".join(table) + "\n"
    )
    (args.out / "coverage.md").write_text(text, encoding="utf-8")
    (args.out / "coverage.json").write_text(json.dumps(rows, indent=2), encoding="utf-8")
    print(text)


if __name__ == "__main__":
    sys.exit(run_script(main))
