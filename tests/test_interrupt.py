"""Ctrl-C means stop: an interrupted solve is never a plan, and a command ends with exit
status 130 and nothing written."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from spm_opt.base.interrupt import solve

pytestmark = pytest.mark.real_time

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "problems" / "craniotomy_bone_flap.toml"
IDENTIFICATION = ROOT / "problems" / "identification.toml"


def _slow_solver() -> ca.Function:
    """An NLP that IPOPT takes seconds over (tight tolerance, many variables)."""
    n = 3000
    x = ca.SX.sym("x", n)
    objective = ca.sumsqr(ca.sin(x) * x - 1) + ca.sum1(ca.exp(ca.sin(x)))
    options = {"max_iter": 3000, "tol": 1e-14, "hessian_approximation": "limited-memory"}
    return ca.nlpsol(
        "slow",
        "ipopt",
        {"x": x, "f": objective, "g": ca.sin(x[1:] * x[:-1])},
        {"ipopt": {**options, "print_level": 0, "sb": "yes"}, "print_time": False},
    )


def test_sigint_during_a_casadi_solve_raises_keyboard_interrupt(capsys):
    solver = _slow_solver()
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            solve(solver, x0=np.full(3000, 0.3), lbg=-0.5, ubg=0.5)
    finally:
        timer.cancel()
    # the signal reached IPOPT mid-solve, which returned as CasADi does on Ctrl-C
    assert solver.stats()["return_status"] == "NonIpopt_Exception_Thrown"
    # CasADi's own warning of it is left out: the command line says it in one line
    assert "KeyboardInterruptException" not in capsys.readouterr().err


def test_a_solve_without_sigint_returns_its_solution():
    x = ca.SX.sym("x")
    solver = ca.nlpsol(
        "quadratic", "ipopt", {"x": x, "f": (x - 2) ** 2}, {"ipopt.print_level": 0, "print_time": 0}
    )
    assert float(solve(solver, x0=0.0)["x"]) == pytest.approx(2.0)


def _interrupt_when(
    arguments: list[str], cue: str, cwd: Path, python: tuple[str, ...] = ()
) -> tuple[int, list[str]]:
    """Run ``python PYTHON -m spm_opt.cli -v ARGUMENTS``, send SIGINT once a stderr line
    holds ``cue``; returns the exit status and the stderr lines."""
    command = [sys.executable, *python, "-m", "spm_opt.cli", "-v", *arguments]
    process = subprocess.Popen(
        command, cwd=cwd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True
    )
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        for line in process.stderr:
            lines.append(line.rstrip("\n"))
            if cue in line and not seen.is_set():
                seen.set()
                process.send_signal(signal.SIGINT)

    reader = threading.Thread(target=read)
    reader.start()
    try:
        status = process.wait(timeout=300)
    finally:
        process.kill()
        reader.join()
    assert seen.is_set(), f"never saw {cue!r}: {lines[-5:]}"
    return status, lines


INTERRUPTED = (130, -signal.SIGINT)
"""How a Ctrl-C'd command ends: status 130, or, when the Ctrl-C landed in code Python ran
from a string (``exec``: dataclasses define their methods so while a module loads), by
SIGINT after the same line and the same clean-up (Python then ends the process so, as its
caller expects of a program it interrupted). A shell reports both as 130."""


def _assert_stopped(status: int, lines: list[str], out: Path) -> None:
    assert status in INTERRUPTED, lines[-5:]
    assert lines[-1] == "spm-opt: interrupted: nothing written"
    assert not any("Traceback" in line or "KeyboardInterrupt" in line for line in lines)
    assert not out.exists() and not out.with_suffix(".json").exists()
    if out.parent.exists():
        assert not [p for p in out.parent.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("module", ["numpy", "scipy.interpolate", "casadi", "spm_opt.planners"])
def test_sigint_while_the_command_imports_is_one_line_and_130(tmp_path, module):
    """``-X importtime`` writes a line as each module's import ends: the signal goes out
    when the one named has been imported, while the modules that import it still are."""
    out = tmp_path / "plan.csv"
    arguments = ["plan", str(PAPER), "--planner", "ocp-min-time", "--out", str(out)]
    status, lines = _interrupt_when(arguments, f" {module}\n", tmp_path, ("-X", "importtime"))
    _assert_stopped(status, lines, out)
    said = [line for line in lines if not line.startswith("import time:")]
    assert said == ["spm-opt: interrupted: nothing written"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("planner", "problem"), [("ocp-min-energy", PAPER), ("excitation", IDENTIFICATION)]
)
def test_sigint_mid_solve_ends_plan_with_130_and_no_plan(tmp_path, planner, problem):
    out = tmp_path / "plan.csv"
    arguments = ["plan", str(problem), "--planner", planner, "--out", str(out)]
    status, lines = _interrupt_when(arguments, "solving (Ctrl-C stops)", tmp_path)
    _assert_stopped(status, lines, out)


@pytest.mark.slow
def test_sigint_mid_fit_ends_identify_with_130_and_no_robot_file(tmp_path):
    import spm_opt as so

    problem = so.load_problem(PAPER)
    plan = so.plan(problem, "toppra")
    log = tmp_path / "run.csv"
    start = plan.position(plan.start_time)
    so.execute(plan, so.SimulatedRobot(problem.robot, start_rad=start), problem, log)
    out = tmp_path / "results" / "robot.toml"
    arguments = ["identify", *[str(log)] * 3, "--problem", str(PAPER), "--out", str(out)]
    arguments += ["--min-speed", "0.001", "--decimation", "1"]
    status, lines = _interrupt_when(arguments, "identify: ", tmp_path)
    _assert_stopped(status, lines, out)
    assert not out.with_suffix(".md").exists() and not out.with_suffix(".png").exists()


def test_the_package_and_the_command_import_nothing_heavy_until_used():
    """So that a Ctrl-C in ``main`` finds its handler (and ``--version`` starts at once):
    the modules a command needs are imported inside it."""
    code = (
        "import sys, spm_opt, spm_opt.cli, spm_opt.base.version\n"
        "heavy = [m for m in ('numpy', 'casadi', 'scipy', 'pandas', 'matplotlib') "
        "if m in sys.modules]\n"
        "print(heavy)\n"
        "missing = [n for n in spm_opt.__all__ if getattr(spm_opt, n, None) is None]\n"
        "print(missing, spm_opt.__version__ == spm_opt.base.version.package_version())"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.splitlines() == ["[]", "[] True"]


def test_a_public_name_stays_what_it_names_when_its_module_is_imported_first():
    code = (
        "import sys, spm_opt.verify.judgement, spm_opt as so\n"
        "home = sys.modules['spm_opt.verify.judgement']\n"
        "print(callable(so.evaluate), so.evaluate is home.evaluate)"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.split() == ["True", "True"]


BLOCKING_CC = """#!/bin/sh
case "$*" in *nlp_*) touch "$0.started"; while [ ! -e "$0.release" ]; do sleep 0.05; done;; esac
exec cc "$@"
"""
"""A compiler that holds every optimal-control library's build until released."""


def test_sigint_while_the_command_waits_for_a_background_compile(tmp_path):
    """The plan is written; the command waits for the library it compiles in the
    background. A Ctrl-C then stops the compiler and ends the command at once."""
    from test_library_cache import compilers_of, wait_until

    compiler = tmp_path / "blocking-cc"
    compiler.write_text(BLOCKING_CC)
    compiler.chmod(0o755)
    cache, out = tmp_path / "cache", tmp_path / "plan.csv"
    command = [sys.executable, "-m", "spm_opt.cli", "-v", "plan", str(PAPER), "--planner"]
    command += ["ocp-min-time", "--out", str(out)]
    environment = {**os.environ, "SPM_OPT_CACHE": str(cache), "CC": str(compiler)}
    process = subprocess.Popen(
        command, env=environment, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    said = []
    try:
        written = process.stdout.readline()  # the command's work is done
        assert written.startswith(f"{out}: ocp-min-time plan"), written
        assert wait_until(Path(f"{compiler}.started").exists, 60)
        for line in process.stderr:  # the command is waiting: the event
            said.append(line.rstrip("\n"))
            if "waiting for the libraries compiling in the background (1)" in line:
                break
        process.send_signal(signal.SIGINT)
        status = process.wait(timeout=30)
    finally:
        process.kill()
        Path(f"{compiler}.release").touch()
    said += process.stderr.read().splitlines()
    assert status in INTERRUPTED and [line for line in said if "info:" not in line] == [
        "spm-opt: interrupted: the command's output stands; the library compiling in the "
        "background is left for the next run"
    ]
    assert out.exists()
    assert wait_until(lambda: not compilers_of(cache), 5), compilers_of(cache)
    assert not [entry for entry in cache.iterdir() if entry.name.startswith("nlp_")]
