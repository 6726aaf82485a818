"""Shared by the benchmark scripts: best-of timing, the timed warm-up, the printed table and the
JSON file."""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import spm_opt as so
from spm_opt.model import dynamics

ROOT = Path(__file__).resolve().parents[1]


def best_of(repeats: int, work: Callable[[], object]) -> float:
    """The shortest of ``repeats`` wall-clock times of ``work()``, s."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


def warm_up(path: Path) -> dict[str, float]:
    """Pay, once and timed, for what every planner and evaluation share: the first
    ``load_problem`` of ``path``, the dynamics model and the compiled torque; s of each."""
    timings = {}
    started = time.perf_counter()
    problem = so.load_problem(path)
    timings["first load_problem"] = time.perf_counter() - started
    started = time.perf_counter()
    dynamics._model()
    timings["dynamics model"] = time.perf_counter() - started
    started = time.perf_counter()
    zeros = np.zeros((1, 2))
    so.inverse_dynamics(problem.robot, zeros, zeros, zeros)
    timings["compiled torque"] = time.perf_counter() - started
    return timings


def throughput_table(
    name: str, rows: dict[str, tuple[int, Callable[[], object]]], reference: str, repeats: int
) -> dict[str, dict[str, float]]:
    """Time every row (sample count, work), print samples per second and the ratio to the
    ``reference`` row, and write ``benchmarks/results/<name>.json``."""
    results = {}
    for label, (count, work) in rows.items():
        seconds = best_of(repeats, work)
        results[label] = {"samples": count, "seconds": seconds, "samples_per_s": count / seconds}
    base = results[reference]["samples_per_s"]
    print(f"{'what':44s} {'samples':>9s} {'best s':>10s} {'samples/s':>12s} {'ratio':>10s}")
    for label, r in results.items():
        r["ratio_to_reference"] = r["samples_per_s"] / base
        print(
            f"{label:44s} {r['samples']:9d} {r['seconds']:10.4f} {r['samples_per_s']:12.3g} "
            f"{r['ratio_to_reference']:9.1f}x"
        )
    print(f"(ratio: against '{reference}', measured in the same run)")
    write_results(name, {"reference": reference, "results": results})
    return results


def write_results(name: str, document: dict) -> Path:
    """Write ``document``, after the machine and Python version, to
    ``benchmarks/results/<name>.json`` and say so."""
    out = ROOT / "benchmarks" / "results" / f"{name}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    document = {"machine": platform.platform(), "python": platform.python_version(), **document}
    out.write_text(json.dumps(document, indent=2) + "\n")
    print(f"written {out.relative_to(ROOT)}")
    return out
