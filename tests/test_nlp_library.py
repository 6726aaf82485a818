"""NLP solvers on compiled libraries of the functions they are assembled from: the
interpreter's solution, a cache on disk keyed by the formulation, the interpreter when no
compiler works, safe concurrent builds."""

import logging
import multiprocessing
import os
import stat
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from test_bad_inputs import run_cli

from spm_opt.base.errors import PlanningError
from spm_opt.model import library_cache
from spm_opt.planners import PLANNERS
from spm_opt.planners.ocp import nlp_library
from spm_opt.planners.ocp.nlp_library import COMPILED, INTERPRETED, LOADED, nlp_solver

OPTIONS = {"ipopt": {"print_level": 0, "sb": "yes"}, "print_time": False, "calc_lam_p": False}
ARGUMENTS = {"x0": [0.0, 0.0], "p": [1.0, 100.0], "lbg": -np.inf, "ubg": 1.5}
ROSENBROCK = (0.907234, 0.822755)  # constrained optimum for p = (1, 100)
NAMES = ("rosenbrock_value", "rosenbrock_jacobian", "rosenbrock_hessian")
ROOT = Path(__file__).resolve().parents[1]


def rosenbrock() -> list[ca.Function]:
    """Rosenbrock's function with parameters (a, b), inside the disc x·x ≤ 1.5: its value,
    Jacobian and Lagrangian Hessian, the pieces the NLP is assembled from."""
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 2)
    sigma, lam = ca.SX.sym("sigma"), ca.SX.sym("lam")
    f = (p[0] - x[0]) ** 2 + p[1] * (x[1] - x[0] ** 2) ** 2
    g = ca.dot(x, x)
    hessian = ca.triu(ca.hessian(sigma * f + lam * g, x)[0])
    return [
        ca.Function(NAMES[0], [x, p], [f, g]),
        ca.Function(NAMES[1], [x, p], [f, g, ca.gradient(f, x), ca.jacobian(g, x)]),
        ca.Function(NAMES[2], [x, p, sigma, lam], [hessian]),
    ]


def assemble(functions: list[ca.Function]) -> tuple[dict, dict]:
    """The NLP and IPOPT's derivative functions from the pieces (SX or compiled)."""
    value, jacobian, hessian = functions
    x, p, lam_f, lam_g = ca.MX.sym("x", 2), ca.MX.sym("p", 2), ca.MX.sym("f"), ca.MX.sym("g")
    f, g = value(x, p)
    _, _, gradient, jac = jacobian(x, p)
    names = ["x", "p"]
    return {"x": x, "p": p, "f": f, "g": g}, {
        "grad_f": ca.Function("nlp_grad_f", [x, p], [f, gradient], names, ["f", "grad_f_x"]),
        "jac_g": ca.Function("nlp_jac_g", [x, p], [g, jac], names, ["g", "jac_g_x"]),
        "hess_lag": ca.Function(
            "nlp_hess_l",
            [x, p, lam_f, lam_g],
            [hessian(x, p, lam_f, lam_g)],
            [*names, "lam_f", "lam_g"],
            ["hess_gamma_x_x"],
        ),
    }


def unused() -> list[ca.Function]:
    raise AssertionError("the functions were built although the library is cached")


def solve(key: str, build=rosenbrock, **kwargs) -> tuple[nlp_library.Solver, np.ndarray]:
    solver = nlp_solver("rosenbrock", "ipopt", key, NAMES, build, assemble, OPTIONS, **kwargs)
    return solver, solver(**ARGUMENTS)["x"].full().ravel()


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(library_cache.CACHE_ENV, str(tmp_path / "cache"))
    yield tmp_path / "cache"
    nlp_library.wait_for_builds()


def failing_compiler(directory, seconds: float = 0.0) -> str:
    """A compiler that always fails, after ``seconds``, with a message."""
    script = directory.parent / "failing-cc"
    script.write_text(f"#!/bin/sh\nsleep {seconds}\necho 'fatal: out of luck' >&2\nexit 1\n")
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return str(script)


def test_compiled_solution_is_the_interpreters(cache):
    x, p = ca.MX.sym("x", 2), ca.MX.sym("p", 2)
    f = (p[0] - x[0]) ** 2 + p[1] * (x[1] - x[0] ** 2) ** 2
    plain = {"x": x, "p": p, "f": f, "g": ca.dot(x, x)}
    interpreted = ca.nlpsol("rosenbrock", "ipopt", plain, OPTIONS)(**ARGUMENTS)
    solver, x = solve("rosenbrock", background=False)
    assert solver.kind == COMPILED
    assert solver.library.parent == cache and solver.library.exists()
    np.testing.assert_allclose(x, interpreted["x"].full().ravel(), rtol=1e-12)
    np.testing.assert_allclose(x, ROSENBROCK, atol=1e-6)
    assert solver.stats()["return_status"] == "Solve_Succeeded"


def test_second_call_loads_without_graph_or_compiler(cache, monkeypatch):
    first, _ = solve("rosenbrock", background=False)

    def no_compiler(*args):
        raise AssertionError("the compiler ran although the library is cached")

    monkeypatch.setattr(nlp_library, "build", no_compiler)
    second, x = solve("rosenbrock", build=unused)
    assert second.kind == LOADED and second.library == first.library
    assert second.seconds < 1.0
    np.testing.assert_allclose(x, ROSENBROCK, atol=1e-6)


def test_background_build_switches_the_solver_to_the_library(cache):
    solver, x = solve("rosenbrock")
    assert solver.kind == INTERPRETED
    nlp_library.wait_for_builds()
    assert solver.library.exists()
    again = solver(**ARGUMENTS)["x"].full().ravel()
    assert solver.kind == LOADED
    np.testing.assert_allclose(again, x, rtol=1e-12)


def test_key_chooses_the_library(cache):
    first, _ = solve("rosenbrock v1", background=False)
    second, _ = solve("rosenbrock v2", background=False)
    assert second.kind == COMPILED and second.library != first.library
    assert nlp_library.library_path(library_cache.compiler(), "rosenbrock v1") == first.library
    assert len(library_cache.entries()) == 2


@pytest.mark.parametrize("missing", ["CC", "PATH"])
def test_no_compiler_means_the_interpreter_and_one_warning(cache, monkeypatch, caplog, missing):
    if missing == "CC":
        monkeypatch.setenv("CC", str(cache / "no-such-compiler"))
    else:
        monkeypatch.delenv("CC", raising=False)
        monkeypatch.setenv("PATH", str(cache.parent))
    with caplog.at_level(logging.WARNING, logger=nlp_library.__name__):
        solver, x = solve("rosenbrock", background=False)
    assert solver.kind == INTERPRETED and solver.library is None
    np.testing.assert_allclose(x, ROSENBROCK, atol=1e-6)
    assert [r.message for r in caplog.records] == [
        "no C compiler: the NLP 'rosenbrock' runs in CasADi's interpreter"
    ]
    assert not cache.exists()


def test_failed_build_means_the_interpreter_and_one_warning(cache, monkeypatch, caplog):
    monkeypatch.setenv("CC", failing_compiler(cache))
    with caplog.at_level(logging.WARNING, logger=nlp_library.__name__):
        solver, x = solve("rosenbrock", background=False)
        again, _ = solve("rosenbrock", background=False)  # built once per process
    assert solver.kind == again.kind == INTERPRETED
    np.testing.assert_allclose(x, ROSENBROCK, atol=1e-6)
    (message,) = [record.message for record in caplog.records]
    assert message.startswith("the NLP stays interpreted: nlp_")
    assert "not built: failing-cc could not compile nlp_" in message
    assert message.endswith(".c: fatal: out of luck")
    assert library_cache.entries() == [] and not list(cache.glob(".build-*"))


def test_too_big_to_compile_is_remembered(cache, monkeypatch, caplog):
    monkeypatch.setattr(nlp_library, "MAX_SOURCE_BYTES", 1000)
    with caplog.at_level(logging.WARNING, logger=nlp_library.__name__):
        solver, x = solve("rosenbrock", background=False)
    assert solver.kind == INTERPRETED
    np.testing.assert_allclose(x, ROSENBROCK, atol=1e-6)
    assert len(caplog.records) == 1 and "too big to compile" in caplog.records[0].message
    assert [entry.name[-8:] for entry in library_cache.entries()] == [".too-big"]

    def no_generation(*args):
        raise AssertionError("the C was generated again")

    monkeypatch.setattr(nlp_library, "_generate", no_generation)
    again, _ = solve("rosenbrock", background=False)
    assert again.kind == INTERPRETED


def build_in_child(cache: str, queue: multiprocessing.Queue) -> None:
    os.environ[library_cache.CACHE_ENV] = cache
    solver, x = solve("rosenbrock concurrent", background=False)
    queue.put((solver.kind, str(solver.library), x.tolist()))


def test_concurrent_builders_leave_one_valid_library(cache):
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    workers = [context.Process(target=build_in_child, args=(str(cache), queue)) for _ in range(2)]
    for worker in workers:
        worker.start()
    results = [queue.get(timeout=120) for _ in workers]
    for worker in workers:
        worker.join(timeout=60)
    assert {kind for kind, _, _ in results} <= {COMPILED, LOADED}
    assert len({library for _, library, _ in results}) == 1
    assert [entry.name for entry in library_cache.entries()] == [os.path.basename(results[0][1])]
    assert not list(cache.glob(".build-*"))
    loaded, x = solve("rosenbrock concurrent", build=unused)
    assert loaded.kind == LOADED
    np.testing.assert_allclose(x, ROSENBROCK, atol=1e-6)


class _BuildsThenFails:
    """A planner that starts a background build (the test's NLP), then fails."""

    name = "builds-then-fails"

    def plan(self, problem):
        solver, _ = solve("rosenbrock in the background")
        assert solver.kind == INTERPRETED
        raise PlanningError("builds-then-fails: never plans")


def test_a_failed_background_build_is_one_line_of_the_command_line(
    cache, monkeypatch, capsys, tmp_path
):
    """The command waits for the build it started, so that its failure (here after the
    command's own end) reaches stderr, in one line."""
    monkeypatch.setenv("CC", failing_compiler(cache, seconds=0.5))
    monkeypatch.setitem(PLANNERS, _BuildsThenFails.name, _BuildsThenFails())
    problem = str(ROOT / "problems" / "craniotomy_bone_flap.toml")
    out = str(tmp_path / "plan.csv")
    status, _ = run_cli(["plan", problem, "--planner", _BuildsThenFails.name, "--out", out])
    assert status == 1
    failed, warning = capsys.readouterr().err.splitlines()
    assert failed == "spm-opt: failed: builds-then-fails: never plans"
    assert warning.startswith("spm-opt: warning: the NLP stays interpreted: nlp_")
    assert warning.endswith(".c: fatal: out of luck")
