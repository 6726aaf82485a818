"""The README's and the compare guide's table of the paper's problem are what `compare`
gives: each duration, ratio and deviation at the digits printed, and "none" exactly where
the judge finds no violation."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import spm_opt as so
from spm_opt.studies.comparison import run_planners

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("README.md", "docs/guide/compare.md")
ROW = re.compile(r"^\| `([\w-]+)`[^|]*\| ([^|]+)\| ([^|]+)\| ([^|]+)\| ([^|]+)\|$", re.MULTILINE)


def table_rows(page: str) -> dict[str, tuple[str, str, str, str]]:
    """The paper's table on a page: planner → (duration, over the bound, max off the
    contour, violations), as printed."""
    text = (ROOT / page).read_text(encoding="utf-8")
    table = text[text.index("| planner | duration | over the bound |") :]
    table = table[: table.index("\n\n")]
    return {m[1]: tuple(cell.strip() for cell in m.groups()[1:]) for m in ROW.finditer(table)}


def agrees(printed: str, value: float) -> bool:
    """Whether ``value`` shows as ``printed`` ("38.20", "6e-8", "< 1e-6", "0.070") at the
    printed digits."""
    printed = printed.split()[0] if not printed.startswith("<") else printed
    if printed.startswith("<"):
        return value < float(printed.lstrip("< "))
    if "e" in printed:
        digits = len(printed.split("e")[0].replace(".", "")) - 1
        return float(f"{value:.{digits}e}") == float(printed)
    decimals = len(printed.split(".")[1]) if "." in printed else 0
    return round(value, decimals) == float(printed)


@pytest.fixture(scope="module")
def compared(paper_problem) -> dict[str, so.Report]:
    planners = list(table_rows(PAGES[0]))
    outcomes = run_planners(paper_problem, planners)
    return {outcome.planner: outcome.report for outcome in outcomes}


def test_the_agreement_rule_reads_the_printed_digits():
    assert agrees("38.20", 38.2049) and not agrees("38.20", 38.206)
    assert agrees("6e-8", 6.2e-8) and not agrees("6e-8", 9.95e-8)
    assert agrees("< 1e-6", 9.95e-8) and not agrees("< 1e-6", 2e-6)
    assert agrees("0.070", 0.0698) and agrees("40", 40.0004)


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_the_pages_table_is_what_compare_gives(page, compared):
    rows = table_rows(page)
    assert set(rows) == set(compared)
    for planner, (duration, ratio, deviation, violations) in rows.items():
        report = compared[planner]
        assert agrees(duration, report.duration_s), (planner, duration, report.duration_s)
        assert agrees(ratio, report.duration_over_lower_bound), (planner, ratio)
        shown = deviation.removesuffix(" mm")
        assert agrees(shown, report.max_contour_deviation_mm), (
            planner,
            shown,
            report.max_contour_deviation_mm,
        )
        assert violations.startswith("none") == (not report.violations), (planner, violations)
