"""`spm-opt sweep` end to end: the shipped 10-flap robustness sweep on two processes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import spm_opt as so

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "problems" / "sweeps" / "random_flaps_small.toml"


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
