"""The docs' tours print what the docs say: each command block followed by a checked output
block is run as written, in a fresh folder, and every line of the output block must be
among what its commands print (stdout and stderr)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MARKER = "<!-- checked: the output of the commands above -->"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
TOURS = ("README.md", "docs/getting-started.md")


def checked_blocks(path: Path) -> list[tuple[list[str], list[str]]]:
    """(commands, expected lines) for each marker in the file: the bash block before it
    and the text block after it."""
    text = path.read_text(encoding="utf-8")
    fences = [(m.start(), m.end(), m.group(1), m.group(2)) for m in FENCE.finditer(text)]
    blocks = []
    for marker in re.finditer(re.escape(MARKER), text):
        before = [f for f in fences if f[1] <= marker.start() and f[2] == "bash"][-1]
        after = next(f for f in fences if f[0] >= marker.end())
        assert after[2] == "text", f"{path}: a checked marker must precede a text block"
        commands = [line for line in before[3].splitlines() if line.strip()]
        blocks.append((commands, [line for line in after[3].splitlines() if line.strip()]))
    return blocks


def test_every_tour_has_checked_blocks():
    assert all(checked_blocks(ROOT / name) for name in TOURS)


@pytest.mark.slow
@pytest.mark.parametrize("name", TOURS)
def test_the_tour_prints_what_its_page_says(name, tmp_path):
    (tmp_path / "problems").symlink_to(ROOT / "problems")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    for commands, expected in checked_blocks(ROOT / name):
        printed = ""
        for command in commands:
            done = subprocess.run(
                command, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True
            )
            assert done.returncode in (0, 1), (command, done.stderr)
            printed += done.stdout + "\n" + done.stderr + "\n"
        missing = [line for line in expected if line not in printed]
        assert not missing, (commands, missing)
