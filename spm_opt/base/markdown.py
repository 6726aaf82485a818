"""Markdown tables: the one helper every report builds its tables with."""

from __future__ import annotations

from collections.abc import Sequence


def cell(value: object) -> str:
    """A value as one markdown table cell: "|" escaped, newlines made spaces."""
    return str(value).replace("|", "\\|").replace("\n", " ")


def markdown_table(headings: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    """The lines of a markdown table: headings, the rule, one line per row.

    Cells are ``str(value)``; format numbers before passing them.
    """
    lines = ["| " + " | ".join(cell(h) for h in headings) + " |", "|" + "---|" * len(headings)]
    return lines + ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
