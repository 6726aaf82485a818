"""Every sub-command with each of its input files (its arguments, and the files they name:
a problem's robot file, a plan's sidecar, a log's header) replaced in turn by an empty
file, a directory, random bytes and a file of the wrong kind (a CSV where a TOML file is
expected, a problem TOML where a CSV or JSON file is, a trajectory CSV given to identify):
always exit status 2 and one ``spm-opt: error:`` line naming the file, never a traceback,
nothing written.

The other arguments are good files (made once for the module): so each case fails for its
one bad file. Commands run in-process (:func:`test_bad_inputs.run_cli`)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_bad_inputs import assert_one_error, run_cli

import spm_opt as so
import spm_opt.execution.emulator
import spm_opt.identify.estimate
import spm_opt.identify.loop
from spm_opt.execution.log import COLUMNS

ROOT = Path(__file__).resolve().parents[1]
HARDWARE_PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"
ROBOT = ROOT / "problems" / "robots" / "prototype.toml"
KINDS = ("empty", "directory", "binary", "wrong-kind")


GOOD = {
    "problem": "problem.toml",
    "robot": "robots/prototype.toml",
    "plan": "plan.csv",
    "run": "run.csv",
    "trace": "true.npz",
    "swing": "swing.csv",
}
"""The good files every case starts from, by role: the hardware problem and its robot file,
its cubic plan (and plan.json), a run of that plan on the simulated robot (and run.json)
with the plant's trace, and a log that identification reads."""


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("good")
    files = {role: folder / name for role, name in GOOD.items()}
    files["robot"].parent.mkdir()
    shutil.copy(ROBOT, files["robot"])
    shutil.copy(HARDWARE_PROBLEM, files["problem"])
    problem = so.load_problem(files["problem"])
    plan = so.plan(problem, "cubic")
    plan.to_csv(files["plan"])
    backend = so.SimulatedRobot(problem.robot, start_rad=plan.position(0.0))
    so.execute(plan, backend, problem, files["run"])
    backend.trace.save(files["trace"])
    _swing_log(files["swing"])
    return files


def _swing_log(path: Path, rows: int = 3000) -> None:
    """A log of ``rows`` samples at 100 Hz, both joints swinging: enough for
    :func:`spm_opt.identify.samples.log_samples`."""
    t = np.arange(rows) / 100.0
    swing = 0.2 * np.sin(2 * np.pi * 0.2 * t)
    table = pd.DataFrame({column: np.zeros(rows) for column in COLUMNS})
    table["time_s"], table["phase"], table["status"] = t, "plan", "ok"
    for joint in (1, 2):
        table[f"position_theta{joint}_rad"] = table[f"goal_theta{joint}_rad"] = swing
        table[f"velocity_theta{joint}_rad_s"] = np.gradient(swing, t)
        table[f"torque_theta{joint}_nm"] = 0.1 * swing
    table.to_csv(path, index=False)


@dataclass(frozen=True)
class Case:
    """A command whose one input file is bad: ``argv(good, bad, out)`` gives its arguments
    with the good files ``good``, the bad file at ``bad`` (named ``name``) and the outputs
    under ``out``; ``wrong`` is the role of the good file of another kind that makes a bad
    one. ``beside``: the bad file is a file the good ones name (``name`` in the good
    folder, e.g. the problem's robot file), in a copy of that folder."""

    argv: Callable[[dict[str, Path], Path, Path], list[str]]
    name: str
    wrong: str
    beside: bool = False


CASES = {
    "plan": Case(lambda g, b, o: ["plan", str(b), "--out", str(o / "p.csv")], "p.toml", "plan"),
    "plan-robot-file": Case(
        lambda g, b, o: ["plan", str(g["problem"]), "--out", str(o / "p.csv")],
        "robots/prototype.toml",
        "plan",
        beside=True,
    ),
    "compare": Case(lambda g, b, o: ["compare", str(b), "--out", str(o)], "p.toml", "plan"),
    "evaluate-problem": Case(
        lambda g, b, o: ["evaluate", str(b), str(g["plan"])], "p.toml", "plan"
    ),
    "evaluate-trajectory": Case(
        lambda g, b, o: ["evaluate", str(g["problem"]), str(b)], "t.csv", "problem"
    ),
    "evaluate-log-header": Case(
        lambda g, b, o: ["evaluate", str(g["problem"]), str(g["run"])],
        "run.json",
        "problem",
        beside=True,
    ),
    "evaluate-trace": Case(
        lambda g, b, o: ["evaluate", str(g["problem"]), str(g["run"]), "--trace", str(b)],
        "t.npz",
        "run",
    ),
    "execute-plan": Case(
        lambda g, b, o: [
            *("execute", str(b), "--problem", str(g["problem"])),
            *("--backend", "sim", "--log", str(o / "run.csv")),
        ],
        "t.csv",
        "problem",
    ),
    "execute-plan-sidecar": Case(
        lambda g, b, o: [
            *("execute", str(g["plan"]), "--problem", str(g["problem"])),
            *("--backend", "sim", "--log", str(o / "run.csv")),
        ],
        "plan.json",
        "problem",
        beside=True,
    ),
    "execute-problem": Case(
        lambda g, b, o: [
            *("execute", str(g["plan"]), "--problem", str(b)),
            *("--backend", "sim", "--log", str(o / "run.csv")),
        ],
        "p.toml",
        "plan",
    ),
    "execute-plant-robot": Case(
        lambda g, b, o: [
            *("execute", str(g["plan"]), "--problem", str(g["problem"]), "--backend", "sim"),
            *("--log", str(o / "run.csv"), "--plant-robot", str(b)),
        ],
        "r.toml",
        "plan",
    ),
    "identify-log": Case(
        lambda g, b, o: [
            *("identify", str(b), "--problem", str(g["problem"]), "--out", str(o / "r.toml"))
        ],
        "l.csv",
        "plan",
    ),
    "identify-problem": Case(
        lambda g, b, o: [
            *("identify", str(g["swing"]), "--problem", str(b), "--out", str(o / "r.toml"))
        ],
        "p.toml",
        "plan",
    ),
    "identify-validate": Case(
        lambda g, b, o: [
            *("identify", str(g["swing"]), "--problem", str(g["problem"])),
            *("--out", str(o / "r.toml"), "--validate", str(b)),
        ],
        "l.csv",
        "plan",
    ),
    "sweep": Case(lambda g, b, o: ["sweep", str(b), "--out", str(o)], "s.toml", "plan"),
    "reproduce": Case(
        lambda g, b, o: ["reproduce", "--problem", str(b), "--out", str(o)], "p.toml", "plan"
    ),
    "emulate-problem": Case(lambda g, b, o: ["emulate", "--problem", str(b)], "p.toml", "plan"),
    "emulate-plant-robot": Case(
        lambda g, b, o: ["emulate", "--plant-robot", str(b)], "r.toml", "plan"
    ),
}


def make_bad(path: Path, kind: str, wrong: Path) -> None:
    """Put a bad file of ``kind`` at ``path``: empty, a directory, 4 kB of random bytes,
    or a copy of ``wrong``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "directory":
        path.mkdir()
    elif kind == "binary":
        path.write_bytes(np.random.default_rng(0).bytes(4096))
    else:
        shutil.copy(wrong, path)


@pytest.fixture
def no_long_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """A case that got past its bad file fails instead of serving for ever (emulate) or
    fitting the good log (identify; then ``--validate``'s file is read)."""

    def served(*args: object, **kwargs: object) -> None:
        raise AssertionError("the emulator would serve: the bad file was accepted")

    monkeypatch.setattr(spm_opt.execution.emulator, "serve", served)
    monkeypatch.setattr(spm_opt.identify.estimate, "identify", lambda robot, samples: None)
    monkeypatch.setattr(spm_opt.identify.loop, "estimate_loops", lambda logs, robot: None)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("case", [pytest.param(c, id=name) for name, c in CASES.items()])
def test_a_bad_file_is_one_line(
    case: Case,
    kind: str,
    good: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    no_long_runs: None,
) -> None:
    out, folder = tmp_path / "out", tmp_path / "in"
    files, bad = good, folder / case.name
    if case.beside:
        origin = good["problem"].parent
        shutil.copytree(origin, folder)
        files = {role: folder / path.relative_to(origin) for role, path in good.items()}
        bad.unlink()
    make_bad(bad, kind, good[case.wrong])
    status, shown = run_cli(case.argv(files, bad, out))
    captured = capsys.readouterr()
    assert_one_error(status, captured.err, (bad.name,), tmp_path, shown)
    written = [p for p in out.rglob("*") if p.is_file()] if out.exists() else []
    assert not written, written
