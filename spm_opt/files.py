"""Writing output files so that a failure never leaves a half-written set."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np


def write_atomically(contents: dict[Path, str | bytes]) -> None:
    """Write every file to a temporary name beside it, then rename them all into place.

    If any write or rename fails, the temporaries and the files already renamed are
    removed and the error is raised: the set appears whole or not at all.
    """
    staged: list[tuple[Path, Path]] = []
    placed: list[Path] = []
    try:
        for path, data in contents.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            staged.append((temporary, path))
            temporary.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
        for temporary, path in staged:
            os.replace(temporary, path)
            placed.append(path)
    except BaseException:
        for temporary, _ in staged:
            temporary.unlink(missing_ok=True)
        for path in placed:
            path.unlink(missing_ok=True)
        raise


def json_default(value: Any) -> Any:
    """``json.dumps``'s ``default`` for numpy arrays and scalars and paths."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
