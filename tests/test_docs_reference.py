"""The file reference (docs/reference/files.md) is up to date and lists every key the
loaders accept: every key read when loading the shipped files, every key the loaders name,
and every setting each planner takes. The README and the command-line page give the
command line's exit statuses."""

from __future__ import annotations

import ast
import dataclasses
import functools
import importlib
import importlib.util
import inspect
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

import spm_opt.model.params
import spm_opt.problem.problem
import spm_opt.studies.sweep.spec
from spm_opt.base.errors import InputError
from spm_opt.base.fields import recording
from spm_opt.cli.parser import EXIT_STATUSES
from spm_opt.model.params import load_robot
from spm_opt.planners import PLANNERS
from spm_opt.problem.problem import load_problem
from spm_opt.studies.sweep.spec import load_sweep_spec

ROOT = Path(__file__).resolve().parents[1]
GENERATOR = ROOT / "docs" / "scripts" / "file_reference.py"
LOADERS = {"problem": load_problem, "robot": load_robot, "sweep": load_sweep_spec}
READERS = {"number", "vector", "string", "boolean", "table", "tables", "raw", "has"}


def _generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location("file_reference", GENERATOR)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def generator() -> ModuleType:
    return _generator()


@pytest.fixture(scope="module")
def page(generator: ModuleType) -> str:
    return generator.PAGE.read_text(encoding="utf-8")


def _sections(page: str) -> dict[str, str]:
    """The page's text under each ``## `` or ``### `` heading, by heading."""
    parts = re.split(r"^#{2,3} (.+)$", page, flags=re.MULTILINE)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def _documented(text: str) -> set[str]:
    """The keys in the first column of the tables in ``text``."""
    return set(re.findall(r"^\| `([^`]+)` \|", text, flags=re.MULTILINE))


def test_the_page_is_up_to_date(generator: ModuleType, page: str) -> None:
    assert page == generator.render(), "run: python docs/scripts/file_reference.py"


def test_every_key_read_from_a_shipped_file_is_documented(generator: ModuleType, page: str) -> None:
    sections = _sections(page)
    for kind, paths in generator.shipped_files().items():
        documented = _documented(sections[generator.SECTIONS[kind][0]])
        for path in paths:
            with recording() as records:
                LOADERS[kind](path)
            keys = {generator._open_key(kind, r.key) for r in records if r.source == str(path)}
            assert keys <= documented, f"{path}: {sorted(keys - documented)} not documented"


def _named_keys(module: ModuleType) -> set[str]:
    """Every key a loader module names literally: the first argument of a Table reader
    (``table.number("mass_kg")``) and the second of a helper given the table
    (``_integer(table, "samples", ...)``)."""
    keys = set()
    for node in ast.walk(ast.parse(Path(module.__file__).read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Call) or not node.args:
            continue
        first = node.args[0]
        if isinstance(node.func, ast.Attribute) and node.func.attr in READERS:
            if isinstance(first, ast.Constant) and isinstance(first.value, str):
                keys.add(first.value)
        elif isinstance(node.func, ast.Name) and node.func.id.startswith("_"):
            second = node.args[1] if len(node.args) > 1 else None
            if isinstance(second, ast.Constant) and isinstance(second.value, str):
                keys.add(second.value)
    return keys


@pytest.mark.parametrize(
    "module", [spm_opt.problem.problem, spm_opt.model.params, spm_opt.studies.sweep.spec]
)
def test_every_key_a_loader_names_is_documented(module: ModuleType, page: str) -> None:
    """Catches keys read only on a path no file takes (then add one to the generator's
    ``other_paths``)."""
    last_parts = {key.rsplit(".", 1)[-1].removesuffix("[]") for key in _documented(page)}
    named = _named_keys(module)
    assert named, "the scan found no key"
    assert named <= last_parts, f"{sorted(named - last_parts)} not documented"


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_each_planners_settings_are_those_it_accepts(name: str, page: str) -> None:
    """A [planner.NAME] table with an unknown key is refused with the keys the planner
    takes: exactly those the page lists."""
    paper = load_problem(ROOT / "problems" / "craniotomy_bone_flap.toml")
    problem = dataclasses.replace(paper, planner_options={name: {"no_such_key": 1}})
    planner = PLANNERS[name]
    with pytest.raises(InputError, match="unknown key") as refused:
        getattr(planner, "settings", planner.plan)(problem)
    allowed = re.search(r"\(allowed: (.*)\)", str(refused.value)).group(1)
    expected = set() if allowed == "none" else set(allowed.split(", "))
    assert _documented(_sections(page)[f"`{name}`"]) == expected


def _exit_status_rows(text: str) -> list[tuple[str, str]]:
    """(status, meaning) of each row of the first table after the "Exit statuses" heading."""
    after = re.split(r"^#+ Exit statuses$", text, flags=re.MULTILINE)[1]
    table = re.search(r"^\|.*?(?=\n\n)", after, flags=re.MULTILINE | re.DOTALL).group(0)
    return re.findall(r"^\| (\d+) \| (.+) \|$", table, flags=re.MULTILINE)


def test_the_readme_and_the_command_line_page_give_the_same_exit_statuses() -> None:
    readme = _exit_status_rows((ROOT / "README.md").read_text(encoding="utf-8"))
    page = _exit_status_rows((ROOT / "docs" / "reference" / "cli.md").read_text("utf-8"))
    assert readme == page
    assert [int(status) for status, _ in page] == list(EXIT_STATUSES)


def _documented_objects() -> list[tuple[str, object]]:
    """Every object the API pages render (``::: dotted.name``), with the public functions,
    methods, properties and classes under it that mkdocstrings shows."""
    targets = sorted(
        {
            line.removeprefix("::: ").strip()
            for page in (ROOT / "docs" / "api").glob("*.md")
            for line in page.read_text(encoding="utf-8").splitlines()
            if line.startswith("::: ")
        }
    )
    found = []
    for target in targets:
        module, _, name = target.rpartition(".")
        try:
            obj = importlib.import_module(target)
        except ModuleNotFoundError:  # an attribute of a module
            obj = getattr(importlib.import_module(module), name)
        found.append((target, obj))
        found += [(f"{target}.{name}", member) for name, member in _public_members(obj)]
    return found


def _public_members(obj: object) -> list[tuple[str, object]]:
    if inspect.ismodule(obj):
        return [
            (name, member)
            for name, member in vars(obj).items()
            if not name.startswith("_")
            and (inspect.isclass(member) or inspect.isfunction(member))
            and member.__module__ == obj.__name__
        ]
    if inspect.isclass(obj):
        members = []
        for name, member in vars(obj).items():
            if name.startswith("_"):
                continue
            member = getattr(member, "__func__", member)  # staticmethod, classmethod
            if isinstance(member, property | functools.cached_property) or inspect.isfunction(
                member
            ):
                members.append((name, member))
        return members
    return []


def test_everything_the_api_pages_render_has_a_docstring() -> None:
    objects = _documented_objects()
    assert len(objects) > 100
    skipped = (dict, list, tuple)  # data (PLANNERS) carries no docstring of its own
    missing = [
        name
        for name, obj in objects
        if not isinstance(obj, skipped) and not (getattr(obj, "__doc__", None) or "").strip()
    ]
    assert missing == []


def test_the_architecture_page_lists_every_module_with_its_job():
    spec = importlib.util.spec_from_file_location(
        "architecture", ROOT / "docs" / "scripts" / "architecture.py"
    )
    generator = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generator)
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    assert page == generator.render(page), "run: python docs/scripts/architecture.py"
