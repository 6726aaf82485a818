"""Writing output files so that a failure never leaves a half-written set."""

from __future__ import annotations

import glob
import os
import socket
from pathlib import Path
from typing import Any

import numpy as np

TEMPORARY_SUFFIX = ".spm-opt.tmp"
"""How a temporary file of :func:`write_atomically` ends: ``.NAME.HOST.PID.spm-opt.tmp``
beside the file NAME it becomes, written by process PID on HOST."""


def write_atomically(contents: dict[Path, str | bytes]) -> None:
    """Write every file to a temporary name beside it, then rename them all into place, in
    the order given.

    If any write or rename fails, the temporaries and the files already renamed are
    removed and the error is raised; once a file was renamed, the old files the set was
    to replace are removed too: the set appears whole or not at all. Only a process killed
    between the renames leaves part of a set (a set that must be verifiable puts first the
    file that records the others' hashes: :meth:`spm_opt.problem.trajectory.Trajectory.csv_files`)
    and a temporary file, which the next write of that file removes.
    """
    staged: list[tuple[Path, Path]] = []
    placed: list[Path] = []
    try:
        for path, data in contents.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            _remove_stale_temporaries(path)
            temporary = path.with_name(
                f".{path.name}.{socket.gethostname()}.{os.getpid()}{TEMPORARY_SUFFIX}"
            )
            staged.append((temporary, path))
            _write_synced(temporary, data.encode("utf-8") if isinstance(data, str) else data)
        for temporary, path in staged:
            os.replace(temporary, path)
            placed.append(path)
    except BaseException:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)
        replaced = [path for _, path in staged] if placed else []
        for path in replaced:
            if not path.is_dir():
                path.unlink(missing_ok=True)
        raise


def _write_synced(path: Path, data: bytes) -> None:
    """Write ``data`` to a new file at ``path`` and flush it to the disk."""
    with open(path, "wb") as file:
        file.write(data)
        file.flush()
        os.fsync(file.fileno())


def _remove_stale_temporaries(path: Path) -> None:
    """Remove the temporary files of ``path`` that a write killed before its renames left:
    those of this host whose process is gone."""
    pattern = f".{glob.escape(path.name)}.*{TEMPORARY_SUFFIX}"
    for temporary in path.parent.glob(pattern):
        writer = temporary.name[len(path.name) + 2 : -len(TEMPORARY_SUFFIX)]
        host, _, pid = writer.rpartition(".")
        if host == socket.gethostname() and pid.isdigit() and not _running(int(pid)):
            temporary.unlink(missing_ok=True)


def _running(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine."""
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError):
        return False
    except PermissionError:  # another user's
        pass
    return True


def json_default(value: Any) -> Any:
    """``json.dumps``'s ``default`` for numpy arrays and scalars and paths."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
