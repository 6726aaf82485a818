"""A plan and its sidecar are one write: a process killed between the two renames leaves
either a consistent pair or a pair reading refuses in one line, and the temporary file it
left is removed by the next write."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spm_opt.base.errors import InputError
from spm_opt.base.files import TEMPORARY_SUFFIX, write_atomically
from spm_opt.problem.trajectory import Trajectory, sidecar_path

TESTS = Path(__file__).resolve().parent


def trajectory(planner: str, duration_s: float) -> Trajectory:
    """A rest-to-rest swing of ``duration_s`` whose sidecar names ``planner``."""
    t = np.linspace(0.0, duration_s, 101)
    s = t / duration_s
    q = np.column_stack([0.3 * s**3 * (10 - 15 * s + 6 * s**2)] * 2)
    qd = np.gradient(q, t, axis=0)
    return Trajectory.from_samples(t, q, qd, np.gradient(qd, t, axis=0), {"planner": planner})


def write_killed(path: str, renames: int) -> None:
    """Write the new plan to ``path`` and die as ``kill -9`` would after ``renames``
    renames (run in a process of its own)."""
    replace, done = os.replace, []

    def replace_or_die(source: str, target: str) -> None:
        if len(done) == renames:
            os._exit(9)
        replace(source, target)
        done.append(target)

    os.replace = replace_or_die
    trajectory("ocp-min-time", 3.0).to_csv(Path(path))


def run_killed(plan: Path, renames: int) -> None:
    script = (
        f"import sys; sys.path.insert(0, {str(TESTS)!r}); from test_plan_files import "
        f"write_killed; write_killed({str(plan)!r}, {renames})"
    )
    result = subprocess.run([sys.executable, "-c", script], timeout=120, check=False)
    assert result.returncode == 9


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(TEMPORARY_SUFFIX))


@pytest.mark.parametrize(("renames", "planner"), [(0, "cubic"), (2, "ocp-min-time")])
def test_killed_before_or_after_the_renames_leaves_a_consistent_pair(
    renames: int, planner: str, tmp_path: Path
) -> None:
    plan = tmp_path / "plan.csv"
    trajectory("cubic", 2.0).to_csv(plan)
    if renames < 2:
        run_killed(plan, renames)
    else:
        trajectory("ocp-min-time", 3.0).to_csv(plan)
    read = Trajectory.from_csv(plan)
    assert read.metadata["planner"] == planner


def test_killed_between_the_renames_is_refused_and_the_next_write_cleans_up(
    tmp_path: Path,
) -> None:
    plan = tmp_path / "plan.csv"
    trajectory("cubic", 2.0).to_csv(plan)
    run_killed(plan, 1)
    # the new sidecar went first: beside the old CSV, its hash does not match
    assert json.loads(sidecar_path(plan).read_text())["planner"] == "ocp-min-time"
    with pytest.raises(InputError, match="inconsistent") as refused:
        Trajectory.from_csv(plan)
    assert "\n" not in str(refused.value) and "plan it again" in str(refused.value)
    assert len(temporaries(tmp_path)) == 1  # the CSV's, of the dead process
    trajectory("toppra", 4.0).to_csv(plan)
    assert Trajectory.from_csv(plan).metadata["planner"] == "toppra"
    assert temporaries(tmp_path) == []


def test_a_first_write_killed_between_the_renames_leaves_no_csv(tmp_path: Path) -> None:
    plan = tmp_path / "plan.csv"
    run_killed(plan, 1)
    with pytest.raises(InputError, match="no such file"):
        Trajectory.from_csv(plan)


def test_a_write_that_fails_between_the_renames_leaves_neither_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plan = tmp_path / "plan.csv"
    trajectory("cubic", 2.0).to_csv(plan)
    replace = os.replace

    def second_fails(source: str, target: str) -> None:
        if Path(target) == plan:
            raise OSError(5, "Input/output error", str(target))
        replace(source, target)

    monkeypatch.setattr(os, "replace", second_fails)
    with pytest.raises(OSError):
        trajectory("ocp-min-time", 3.0).to_csv(plan)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_live_writer_s_temporary_is_kept(tmp_path: Path) -> None:
    """Only the temporaries of processes that are gone are removed."""
    target = tmp_path / "plan.json"
    gone = [sys.executable, "-c", "import os; print(os.getpid())"]
    dead = subprocess.run(gone, check=True, capture_output=True, text=True)
    host = socket.gethostname()
    stale = tmp_path / f".plan.json.{host}.{dead.stdout.strip()}{TEMPORARY_SUFFIX}"
    live = tmp_path / f".plan.json.{host}.{os.getppid()}{TEMPORARY_SUFFIX}"
    for temporary in (stale, live):
        temporary.write_text("{}")
    write_atomically({target: "{}\n"})
    assert temporaries(tmp_path) == [live.name]


def test_a_plan_without_the_hash_still_reads(tmp_path: Path) -> None:
    """A sidecar written before plans recorded their CSV's hash is read as it is."""
    plan = tmp_path / "plan.csv"
    trajectory("cubic", 2.0).to_csv(plan)
    sidecar = json.loads(sidecar_path(plan).read_text())
    del sidecar["samples"]
    sidecar_path(plan).write_text(json.dumps(sidecar))
    assert Trajectory.from_csv(plan).metadata["planner"] == "cubic"
