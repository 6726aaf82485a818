"""The reporting layer (spm_opt/report/): it never imports the modules that call it, it
holds each column's heading once, every markdown table is built by its one helper, and
the comparison states the evaluator's tolerance as spm_opt.judge.limits gives it."""

from __future__ import annotations

import ast
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

import spm_opt
from spm_opt.judge import limits
from spm_opt.studies import comparison, reproduce
from spm_opt.studies.comparison import Outcome, comparison_markdown

PACKAGE = Path(spm_opt.__file__).resolve().parent
CALLERS = ("spm_opt.studies", "spm_opt.identify", "spm_opt.cli")
"""The layers above the report, which call it (the hardware verification is a study now)."""


def imported(path: Path) -> set[str]:
    """Every module ``path`` imports, anywhere in it (functions and TYPE_CHECKING too)."""
    package = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts[:-1])
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            module = ".".join(part for part in (base, node.module or "") if part)
            names.add(module)
            names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def test_the_report_layer_never_imports_its_callers() -> None:
    modules = sorted((PACKAGE / "report").glob("*.py"))
    assert {"columns.py", "comparison_figures.py"} <= {p.name for p in modules}
    for path in modules:
        callers = {name for name in imported(path) if name.startswith(CALLERS)}
        assert not callers, f"{path.name} imports {sorted(callers)}"


def test_no_figure_module_imports_the_comparison() -> None:
    figures = sorted(PACKAGE.rglob("*figures*.py"))
    assert PACKAGE / "report" / "comparison_figures.py" in figures
    for path in figures:
        assert not any(name.startswith("spm_opt.studies.comparison") for name in imported(path)), (
            path
        )


def test_each_column_has_its_words_once() -> None:
    from spm_opt.report.columns import COLUMN, COLUMNS, DERIVED, HEADINGS

    assert isinstance(COLUMNS, tuple) and COLUMNS == comparison.COLUMNS == tuple(COLUMN)
    assert set(HEADINGS) == set(COLUMN) | set(DERIVED)
    for name, (heading, label) in HEADINGS.items():
        assert heading and label, name
    assert HEADINGS["max_tool_speed_mm_s"] == ("max tool mm/s", "max tool speed (mm/s)")


@pytest.fixture
def failed_only() -> list[Outcome]:
    """Outcomes without a plan: the comparison's markdown, with no planner run."""
    return [Outcome("a|b", 0.5, error="PlanningError: none"), Outcome("cubic", 0.1, error="x")]


def test_the_comparison_takes_its_headings_from_the_columns(
    paper_problem, failed_only: list[Outcome], monkeypatch: pytest.MonkeyPatch
) -> None:
    from spm_opt.report import columns

    renamed = columns.COLUMN["duration_s"]._replace(heading="cut time s")
    monkeypatch.setitem(columns.COLUMN, "duration_s", renamed)
    text = comparison_markdown(paper_problem, failed_only)
    assert "| cut time s |" in text and "| duration s |" not in text


def test_the_comparison_states_the_evaluators_tolerance(
    paper_problem, failed_only: list[Outcome], monkeypatch: pytest.MonkeyPatch
) -> None:
    assert limits.tolerance_note() in comparison_markdown(paper_problem, failed_only)
    monkeypatch.setattr(
        limits, "tolerance_note", lambda: "Tolerance: as spm_opt.judge.limits says."
    )
    text = comparison_markdown(paper_problem, failed_only)
    assert "Tolerance: as spm_opt.judge.limits says." in text
    assert "0.5 %" not in text and "0.01 mm" not in text


def cells(line: str) -> list[str]:
    """The cells of a markdown table line, split on the pipes that are not escaped."""
    return re.split(r"(?<!\\)\|", line.strip())[1:-1]


def assert_tables_hold_their_cells(text: str, expected: str) -> None:
    """Every table line of ``text`` has as many cells as its table's heading, and the
    cell ``expected`` (with its "|" escaped) is one of them."""
    width = None
    for line in text.splitlines():
        if not line.startswith("|"):
            width = None
            continue
        width = width or len(cells(line))
        assert len(cells(line)) == width, line
    assert any(expected in cells(line) for line in text.splitlines() if line.startswith("|"))


def test_a_pipe_in_a_cell_keeps_the_comparison_table_whole(
    paper_problem, failed_only: list[Outcome]
) -> None:
    text = comparison_markdown(paper_problem, failed_only)
    assert_tables_hold_their_cells(text, r" a\|b ")


def test_a_pipe_in_a_cell_keeps_the_reproduction_tables_whole() -> None:
    row = reproduce.Table3Row("a1", "0.1", 0.1, 0.0, reproduce.AGREES, note="|x| < 1")
    assert_tables_hold_their_cells(reproduce.table3_markdown([row]), r" \|x\| < 1 ")
    table4 = reproduce.Table4Row(1, 0.11, "0.11", 1e-16, 1e-16, 1e-13, 1e-13, "1|2")
    results = SimpleNamespace(
        rows=[table4],
        multibody_friction_relative=[1e-15, 2e-15],
        power_balance_relative=1e-12,
        open_loop_deviation_deg=1e-6,
    )
    assert_tables_hold_their_cells(reproduce.table4_markdown(results, 0.24), r" 1\|2 ")
