"""The run of ``spm-opt``: parse, log to stderr, run the command, and end in an exit status.

The outcome is one line on stderr; :data:`~spm_opt.cli.parser.EXIT_STATUSES` says what each
status means.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from spm_opt.base.errors import PlanningError, RunInterrupted, SpmOptError, StopAsked, require
from spm_opt.cli.commands import COMMANDS, GateFailed, optional_modules
from spm_opt.cli.parser import build_parser


class _OneLine(logging.Formatter):
    """A log record as ``spm-opt: warning: message`` (the level in lower case)."""

    def format(self, record: logging.LogRecord) -> str:
        return f"spm-opt: {record.levelname.lower()}: {record.getMessage()}"


def _log_to_stderr(verbosity: int) -> logging.Handler:
    """Send the library's log to stderr, warnings and worse (-v: info, -vv: debug too);
    returns the handler, for :func:`main` to remove."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLine())
    logger = logging.getLogger("spm_opt")
    logger.setLevel({0: logging.WARNING, 1: logging.INFO}.get(verbosity, logging.DEBUG))
    logger.addHandler(handler)
    return handler


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status. A Ctrl-C at any point of it, while
    the command's modules are imported too, ends it with one line and status 130."""
    try:
        args = build_parser().parse_args(argv)
        logger = logging.getLogger("spm_opt")
        level = logger.level
        handler = _log_to_stderr(args.verbose)
        try:
            status = _run(args)
            try:
                _wait_for_builds()
            except KeyboardInterrupt:
                return _interrupted(
                    "the command's output stands; the library compiling in the background "
                    "is left for the next run"
                )
            return status
        finally:
            logger.removeHandler(handler)
            logger.setLevel(level)
    except KeyboardInterrupt:
        return _interrupted()


def _run(args: argparse.Namespace) -> int:
    """Run the parsed command; returns the exit status."""
    try:
        for module, needed_by in optional_modules(args):
            require(module, needed_by)
        COMMANDS[args.command](args)
    except GateFailed as failed:
        print(f"spm-opt: {failed}", file=sys.stderr)
        return 1
    except (SpmOptError, OSError) as error:
        return _ended_by("spm-opt", error)
    return 0


def run_script(main: Callable[[], int | None]) -> int:
    """Run an experiment script's ``main``; returns its exit status. An error ends it as
    it ends ``spm-opt`` (:data:`~spm_opt.cli.parser.EXIT_STATUSES`: one line on stderr,
    naming the script; a bad input 2, a plan that could not be made 1, a Ctrl-C 130), and
    a SIGINT or SIGTERM that stopped one of its runs with 128 plus the signal's number."""
    name = Path(sys.argv[0]).name
    try:
        return main() or 0
    except (SpmOptError, OSError) as error:
        return _ended_by(name, error)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130


def _ended_by(name: str, error: SpmOptError | OSError) -> int:
    """Say in one line on stderr, after ``name``, how ``error`` ended the program; returns
    the exit status."""
    if isinstance(error, StopAsked):
        print(f"{name}: stopped: {error}", file=sys.stderr)
        return 128 + error.signal_number
    if isinstance(error, RunInterrupted):
        print(f"{name}: interrupted: {error}", file=sys.stderr)
        return 130
    if isinstance(error, PlanningError):  # a valid problem the planner could not plan
        print(f"{name}: failed: {error}", file=sys.stderr)
        return 1
    if isinstance(error, OSError):  # an output path that cannot be written: the user can fix it
        where = f"{error.filename}: " if error.filename else ""
        print(f"{name}: error: {where}cannot write ({error.strerror or error})", file=sys.stderr)
    else:
        print(f"{name}: error: {error}", file=sys.stderr)
    return 2


def _wait_for_builds() -> None:
    """Wait for the libraries a planner compiles in the background, so that a failed
    build's warning reaches stderr (:mod:`spm_opt.planners.ocp.nlp_library`)."""
    library = sys.modules.get("spm_opt.planners.ocp.nlp_library")
    if library is not None:
        library.wait_for_builds()


def _interrupted(what: str = "nothing written") -> int:
    """After a Ctrl-C: the compilers the command started stop (the process need not wait
    for them), and a second Ctrl-C ends the process at once; one line; status 130."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_DFL)
    library_cache = sys.modules.get("spm_opt.model.library_cache")
    if library_cache is not None:
        library_cache.stop_compilers()
    print(f"spm-opt: interrupted: {what}", file=sys.stderr)
    return 130
