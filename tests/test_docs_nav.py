"""Every page of the documentation is in the site's navigation: ``mkdocs build --strict``
refuses a page left out of ``nav``, and this finds it in the test run, before the build."""

from __future__ import annotations

from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _pages(entry: object) -> list[str]:
    """The page paths under one entry of mkdocs.yml's ``nav``."""
    if isinstance(entry, str):
        return [entry]
    if isinstance(entry, list):
        return [page for item in entry for page in _pages(item)]
    if isinstance(entry, dict):
        return [page for value in entry.values() for page in _pages(value)]
    return []


def test_every_page_is_in_the_navigation_and_every_entry_exists() -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    listed = set(_pages(config["nav"]))
    excluded = [line.strip() for line in config.get("exclude_docs", "").splitlines()]
    pages = {
        path.relative_to(DOCS).as_posix()
        for path in DOCS.rglob("*.md")
        if not any(path.relative_to(DOCS).as_posix().startswith(e) for e in excluded if e)
    }
    assert sorted(pages - listed) == [], "pages missing from mkdocs.yml's nav"
    assert sorted(listed - pages) == [], "nav entries with no page"
