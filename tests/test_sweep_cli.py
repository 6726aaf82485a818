"""`spm-opt sweep` end to end: the shipped 10-flap robustness sweep on two processes;
resuming after failures and after a change of the code."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import spm_opt as so
from spm_opt.studies.sweep.spec import load_sweep_spec

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "problems" / "sweeps" / "random_flaps_small.toml"
PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"


def tiny_spec(directory: Path) -> Path:
    """Two tasks of the cubic planner (milliseconds each) on the paper's problem."""
    path = directory / "tiny.toml"
    path.write_text(
        f'name = "tiny"\nproblem = {json.dumps(str(PROBLEM))}\nplanners = ["cubic"]\n'
        '[grid]\n"limits.max_tool_speed_mm_s" = [2.0, 3.0]\n'
    )
    return path


def lines(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]


def counts(out: Path) -> list[str]:
    """The summary's counts of all tasks: tasks, ok, with violations, failed."""
    summary = (out / "summary.md").read_text()
    row = next(line for line in summary.splitlines() if line.startswith("| all |"))
    return [cell.strip() for cell in row.strip("| ").split(" | ")][1:]


@pytest.mark.slow
def test_the_small_flap_sweep_runs_writes_its_report_and_resumes(tmp_path):
    out = tmp_path / "flaps"
    command = [sys.executable, "-m", "spm_opt.cli", "sweep", str(SMALL), "--out", str(out)]
    first = subprocess.run([*command, "--workers", "2"], capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    table = so.load_sweep(out)
    assert len(table) == 10 * 4 and table["key"].is_unique
    assert set(table["planner"]) == {"cubic", "toppra", "ruckig", "ocp-min-time"}
    assert sorted(set(table["flap"])) == list(range(10))
    assert table["flap_size_mm"].between(20.0, 50.0).all()
    planned = table[table["status"] != "failed"]
    assert len(planned) >= 30  # every planner plans most small flaps
    summary = (out / "summary.md").read_text()
    assert "random_flaps_small" in summary or "10 random bone flaps" in summary
    for name in ("flap_robustness.png", "results.parquet", "results.csv"):
        assert (out / name).is_file()
    lines = (out / "results.jsonl").read_text().splitlines()
    assert all(json.loads(line)["key"] for line in lines)

    again = subprocess.run(command, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert "40 already done, 0 run" in again.stderr
    assert (out / "results.jsonl").read_text().splitlines() == lines


def test_bad_sweep_options_are_one_line_errors(tmp_path, capsys):
    from spm_opt.cli import main

    assert main(["sweep", str(SMALL), "--out", str(tmp_path / "x"), "--workers", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["spm-opt: error: --workers 0: expected a whole number of processes, >= 1"]
    assert main(["sweep", str(SMALL), "--out", str(tmp_path / "x"), "--scheduler", "x"]) == 2
    assert "--scheduler 'x'" in capsys.readouterr().err


def test_an_unreachable_scheduler_leaves_nothing_behind(tmp_path, capsys):
    from spm_opt.cli import main

    out = tmp_path / "never"
    assert main(["sweep", str(SMALL), "--out", str(out), "--scheduler", "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scheduler tcp://127.0.0.1:1: cannot connect" in err[0]
    assert not out.exists()


def test_resume_runs_machine_failures_again_and_retry_failed_the_others(tmp_path, capsys):
    from spm_opt.cli import main

    spec, out = tiny_spec(tmp_path), tmp_path / "out"
    result, machine = (task.key for task in load_sweep_spec(spec).tasks())
    out.mkdir()
    failed = {"sweep": "tiny", "planner": "cubic", "status": "failed", "error": "E: e"}
    (out / "results.jsonl").write_text(
        json.dumps({"key": result, **failed, "failure": "result"})
        + "\n"
        + json.dumps({"key": machine, **failed, "failure": "machine"})
        + "\n"
    )
    assert main(["sweep", str(spec), "--out", str(out)]) == 0
    assert "2 tasks, 1 already done, 1 run (1 again, 0 failed)" in capsys.readouterr().err
    assert [row["key"] for row in lines(out)] == [result, machine, machine]
    assert counts(out) == ["2", "0", "1", "1"]  # cubic breaks limits: "with violations"

    assert main(["sweep", str(spec), "--out", str(out), "--retry-failed"]) == 0
    assert "2 tasks, 1 already done, 1 run (1 again, 0 failed)" in capsys.readouterr().err
    assert [row["key"] for row in lines(out)] == [result, machine, machine, result]
    assert counts(out) == ["2", "0", "2", "0"]  # each task once, its newest row
    assert len(so.load_sweep(out)) == 2


def test_rows_of_other_code_are_stale_and_computed_again(tmp_path, capsys):
    """A sweep run by a changed copy of the package (its rows carry other keys), then
    resumed by this one: every task runs again, and the summary shows this code's rows and
    counts the others as stale."""
    from spm_opt.cli import main

    spec, out = tiny_spec(tmp_path), tmp_path / "out"
    changed = tmp_path / "changed" / "spm_opt"
    shutil.copytree(ROOT / "spm_opt", changed, ignore=shutil.ignore_patterns("__pycache__"))
    with open(changed / "studies" / "sweep" / "task.py", "a") as source:
        source.write("\n# a change of the code\n")
    command = [
        sys.executable,
        "-c",
        "from spm_opt.studies.sweep.runner import run_sweep\n"
        "from spm_opt.studies.sweep.spec import load_sweep_spec\n"
        f"run_sweep(load_sweep_spec({str(spec)!r}).tasks(), {str(out)!r}, progress=False)",
    ]
    environment = {**os.environ, "PYTHONPATH": str(changed.parent)}
    other = subprocess.run(  # not in the repository's root: it would come first on the path
        command, env=environment, cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert other.returncode == 0, other.stderr
    before = {row["key"] for row in lines(out)}
    assert len(before) == 2

    assert main(["sweep", str(spec), "--out", str(out)]) == 0
    assert "2 tasks, 0 already done, 2 run" in capsys.readouterr().err
    now = {row["key"] for row in lines(out)} - before
    assert now == {task.key for task in load_sweep_spec(spec).tasks()} and len(now) == 2
    assert "- 2 stale rows in results.jsonl" in (out / "summary.md").read_text()
    assert counts(out)[0] == "2"
    assert len((out / "results.csv").read_text().splitlines()) == 1 + 2
