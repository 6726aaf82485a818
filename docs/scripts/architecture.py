"""Write docs/architecture.md's table of modules and its figure of the layers, from the
code: the layers are import-linter's contract in pyproject.toml, each module's line is the
first sentence of its docstring, and the arrows are the imports between layers.

    python docs/scripts/architecture.py

``tests/test_docs_reference.py`` checks that the page's table is up to date.
"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "architecture.md"
FIGURE = ROOT / "docs" / "architecture.png"
PACKAGE = ROOT / "spm_opt"
SENTENCE_END = re.compile(r"(?<!\bFigs)(?<!\bFig)(?<!\bEqs)(?<!\bEq)(?<!e\.g)\.\s+(?=[A-Z(])")
"""The end of a docstring's first sentence (not an abbreviation's point)."""
BEGIN = "<!-- the modules: written by docs/scripts/architecture.py -->"
END = "<!-- end of the modules -->"


def layers() -> list[str]:
    """The layers, bottom to top, as pyproject.toml declares them (their short names)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    (contract,) = [c for c in config["tool"]["importlinter"]["contracts"] if c["type"] == "layers"]
    return [name.removeprefix("spm_opt.") for name in reversed(contract["layers"])]


def job(path: Path) -> str:
    """The first sentence of a module's docstring, on one line."""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    first = " ".join(doc.split("\n\n")[0].split())
    end = SENTENCE_END.search(first)
    return (first if end is None else first[: end.start() + 1]).replace("|", "\\|")


def modules(layer: str) -> list[Path]:
    """The layer's modules: its file, or every file of its package (``__init__`` where it
    says more than its package's name)."""
    single = PACKAGE / f"{layer}.py"
    if single.exists():
        return [single]
    return sorted(
        p
        for p in (PACKAGE / layer).rglob("*.py")
        if p.name != "__init__.py" or len(p.read_text(encoding="utf-8").splitlines()) > 3
    )


def table() -> str:
    """The markdown table: layer, module, job; top layer first (no line counts: the page
    changes when a module comes, goes or changes its job, not at every edit)."""
    rows = ["| layer | module | its job |", "|---|---|---|"]
    for layer in reversed(layers()):
        for path in modules(layer):
            name = str(path.relative_to(ROOT))
            rows.append(f"| `{layer}` | `{name}` | {job(path)} |")
    return "\n".join(rows)


def render(page: str) -> str:
    """The page with its table replaced by the code's."""
    head, rest = page.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{table()}\n{END}{tail}"


def figure() -> None:
    """The layers as stacked boxes, each with its line count and its modules' count."""
    from matplotlib.figure import Figure
    from matplotlib.patches import FancyBboxPatch

    names = layers()
    figure = Figure(figsize=(8, 7), layout="constrained")
    axis = figure.subplots()
    for level, layer in enumerate(names):
        paths = modules(layer)
        lines = sum(len(p.read_text(encoding="utf-8").splitlines()) for p in paths)
        axis.add_patch(
            FancyBboxPatch(
                (0.1, level + 0.1), 0.8, 0.8, boxstyle="round,pad=0.02", fc="#dde8f5", ec="k"
            )
        )
        axis.text(0.5, level + 0.5, f"{layer}/", ha="center", va="center", fontsize=12)
        axis.text(
            0.88,
            level + 0.5,
            f"{len(paths)} module{'s' * (len(paths) != 1)}, {lines:,} lines",
            ha="right",
            va="center",
            fontsize=8,
            color="#444",
        )
        if level:
            axis.annotate(
                "",
                (0.05, level - 0.1),
                (0.05, level + 0.5),
                arrowprops={"arrowstyle": "->", "color": "#888"},
            )
    axis.set_xlim(0, 1)
    axis.set_ylim(0, len(names))
    axis.axis("off")
    axis.set_title("spm_opt's layers, bottom to top: each imports only those below it")
    figure.savefig(FIGURE, dpi=120)


if __name__ == "__main__":
    PAGE.write_text(render(PAGE.read_text(encoding="utf-8")), encoding="utf-8")
    figure()
