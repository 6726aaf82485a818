"""A missing optional package, on every command that needs it: one line on stderr naming
the extra to install, exit status 2, nothing written.

Each case runs the command line in its own process with the module made unimportable
(``sys.modules[name] = None``, as Python does for a module that failed to import).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import spm_opt as so

ROOT = Path(__file__).resolve().parents[1]
PAPER_PROBLEM = ROOT / "problems" / "craniotomy_bone_flap.toml"
HARDWARE_PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"
SKULL_PROBLEM = ROOT / "problems" / "skull_flap.toml"

_WITHOUT = (
    "import sys; sys.modules[sys.argv.pop(1)] = None; "
    "from spm_opt.cli import main; sys.exit(main(sys.argv[1:]))"
)


def run_without(module: str, argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``spm-opt argv`` in a new process in which ``module`` cannot be imported."""
    command = [sys.executable, "-c", _WITHOUT, module, *argv]
    return subprocess.run(
        command, capture_output=True, text=True, timeout=300, cwd=cwd, check=False
    )


@pytest.fixture(scope="module")
def sweep_spec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-task sweep (cubic, one tool-speed limit): quick even where it runs."""
    spec = tmp_path_factory.mktemp("spec") / "one_task.toml"
    spec.write_text(
        f'name = "one_task"\nproblem = "{PAPER_PROBLEM.as_posix()}"\nplanners = ["cubic"]\n\n'
        '[grid]\n"limits.max_tool_speed_mm_s" = [3.0]\n',
        encoding="utf-8",
    )
    return spec


@pytest.fixture(scope="module")
def hardware_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    plan = tmp_path_factory.mktemp("plan") / "plan.csv"
    so.plan(so.load_problem(HARDWARE_PROBLEM), "cubic").to_csv(plan)
    return plan


def _argv(command: str, out: Path, sweep_spec: Path, hardware_csv: Path) -> list[str]:
    if command == "sweep":
        return ["sweep", str(sweep_spec), "--out", str(out)]
    if command == "sweep-dask":
        return ["sweep", str(sweep_spec), "--out", str(out), "--scheduler", "local"]
    if command == "reproduce":
        return ["reproduce", "--problem", str(PAPER_PROBLEM), "--out", str(out)]
    if command == "plan-skull":
        return ["plan", str(SKULL_PROBLEM), "--planner", "cubic", "--out", str(out / "p.csv")]
    if command == "review":
        return ["review", str(HARDWARE_PROBLEM), str(hardware_csv), "--out", str(out)]
    assert command == "execute-dynamixel"
    return [
        "execute",
        str(hardware_csv),
        "--problem",
        str(HARDWARE_PROBLEM),
        "--backend",
        "dynamixel",
        "--port",
        "/dev/null",
        "--log",
        str(out / "run.csv"),
    ]


@pytest.mark.parametrize(
    ("module", "package", "extra", "command"),
    [
        ("tqdm", "tqdm", "sweep", "sweep"),
        ("pyarrow", "pyarrow", "sweep", "sweep"),
        ("distributed", "distributed", "sweep", "sweep-dask"),
        ("dynamixel_sdk", "dynamixel-sdk", "hardware", "execute-dynamixel"),
        ("serial", "pyserial", "hardware", "execute-dynamixel"),
        ("mujoco", "mujoco", "verify", "reproduce"),
        ("trimesh", "trimesh", "skull", "plan-skull"),
        ("plotly", "plotly", "skull", "review"),
    ],
)
def test_a_missing_optional_package_names_its_extra(
    module: str,
    package: str,
    extra: str,
    command: str,
    tmp_path: Path,
    sweep_spec: Path,
    hardware_csv: Path,
) -> None:
    out = tmp_path / "out"
    result = run_without(module, _argv(command, out, sweep_spec, hardware_csv), tmp_path)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("spm-opt: error: ")
    assert f'needs {package}: pip install -e ".[{extra}]"' in lines[0]
    assert result.returncode == 2
    assert result.stdout == ""
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []
