"""Output paths checked before any work: a folder that cannot be made or written is
refused in one line naming the option, not after minutes of planning."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from spm_opt.base.errors import InputError


def check_output_directory(path: Path, option: str) -> None:
    """Refuse ``path`` as an output directory unless it is one, or can be made, and can be
    written (a probe file is made and removed in the nearest existing folder)."""
    if path.exists() and not path.is_dir():
        raise InputError(f"{option} {path}: is a file, expected a directory")
    _check_writable(_nearest_existing(path, option), path, option)


def check_output_file(path: Path, option: str) -> None:
    """Refuse ``path`` as an output file if it is a directory, or if its folder cannot be
    made or written."""
    if path.is_dir():
        raise InputError(f"{option} {path}: is a directory, expected a file name")
    _check_writable(_nearest_existing(path.parent, option), path, option)


def _nearest_existing(path: Path, option: str) -> Path:
    """``path`` or its nearest existing ancestor, which must be a directory."""
    folder = path.absolute()
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"{option} {path}: {folder} is a file, so no folder can be made in it")
    return folder


def _check_writable(folder: Path, path: Path, option: str) -> None:
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".spm-opt-probe-"):
            pass
    except OSError as error:
        reason = os.strerror(error.errno) if error.errno else str(error)
        raise InputError(f"{option} {path}: cannot write in {folder} ({reason})") from None
