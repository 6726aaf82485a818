"""``spm-opt execute --interactive`` in a real terminal: a pseudo-terminal is the command's
stdin, stdout and stderr, and the test types the keys a surgeon would."""

from __future__ import annotations

import json
import os
import pty
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import HARDWARE_PROBLEM

import spm_opt as so
from spm_opt.execution import read_log

pytestmark = pytest.mark.real_time


class Terminal:
    """A command on a pseudo-terminal; collects everything it writes."""

    def __init__(self, command: list[str], cwd: Path) -> None:
        master, slave = pty.openpty()
        self._master = master
        self.process = subprocess.Popen(
            command, stdin=slave, stdout=slave, stderr=slave, cwd=cwd, close_fds=True
        )
        os.close(slave)
        self._chunks: list[bytes] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self._master, 4096)
            except OSError:  # the command ended and closed the terminal
                return
            if not data:
                return
            self._chunks.append(data)

    @property
    def text(self) -> str:
        return b"".join(self._chunks).decode(errors="replace")

    def type(self, keys: str) -> None:
        os.write(self._master, keys.encode())

    def wait_for(self, pattern: str, after: int = 0, timeout_s: float = 30.0) -> int:
        """Wait until ``pattern`` (a regex) shows in the output past ``after``; returns
        where its match ends."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            found = re.search(pattern, self.text[after:])
            if found:
                return after + found.end()
            if self.process.poll() is not None:
                break
            time.sleep(0.02)
        raise AssertionError(f"{pattern!r} never showed; the terminal shows:\n{self.text[-2000:]}")

    def close(self) -> int:
        status = self.process.wait(timeout=30)
        self._reader.join(timeout=5)
        os.close(self._master)
        return status


@pytest.fixture(scope="module")
def plan_file(hardware_problem, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("plan") / "plan.csv"
    so.plan(hardware_problem, "cubic").to_csv(path)
    return path


@pytest.mark.slow
def test_keys_hold_resume_change_the_feed_and_stop(plan_file, tmp_path):
    log = tmp_path / "run.csv"
    command = [sys.executable, "-m", "spm_opt.cli", "execute", str(plan_file)]
    command += ["--problem", str(HARDWARE_PROBLEM), "--backend", "sim", "--log", str(log)]
    terminal = Terminal([*command, "--interactive"], tmp_path)
    try:
        at = terminal.wait_for(r"keys: space hold/resume")
        at = terminal.wait_for(r"mm \(\s*\d+%\)\s+feed\s+100%.*running", at)
        time.sleep(1.0)
        terminal.type(" ")
        at = terminal.wait_for(r"feed\s+0%.*held", at)
        for _ in range(2):  # while held: the override the resume goes on at
            terminal.type("-")
            time.sleep(0.3)
        terminal.type(" ")
        at = terminal.wait_for(r"feed\s+80%.*running", at)
        terminal.type("+")
        at = terminal.wait_for(r"feed\s+90%.*running", at)
        terminal.type("q")
        terminal.wait_for(r"safe stop: interrupted \(operator pressed q\); travel after", at)
    finally:
        status = terminal.close()
    assert status == 1
    table, header = read_log(log)
    events = [e["event"] for e in header["feed_events"]]
    assert events[:2] == ["hold", "held"]
    assert [e for e in events if e.startswith("feed ")] == ["feed 90%", "feed 80%", "feed 90%"]
    assert events.index("resume") > events.index("feed 80%")
    assert header["reason"] == "interrupted (operator pressed q)"
    assert table["phase"].iloc[-1] == "hold" and header["at_rest"]
    assert json.loads(log.with_suffix(".json").read_text())["settings"]["feed"] == 1.0


def test_without_a_terminal_the_keys_are_off_and_the_run_goes_on(plan_file, tmp_path):
    log = tmp_path / "run.csv"
    command = [sys.executable, "-m", "spm_opt.cli", "execute", str(plan_file)]
    command += ["--problem", str(HARDWARE_PROBLEM), "--backend", "sim", "--log", str(log)]
    done = subprocess.run(
        [*command, "--interactive"], stdin=subprocess.DEVNULL, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "--interactive: stdin is not a terminal, so the keys are off" in done.stderr
    assert "\r" not in done.stderr  # no live view either: stderr is not a terminal
    _, header = read_log(log)
    assert header["completed"] and header["feed_events"] == []
