"""A tracker's recording from the files labs export, as one marker's track (m, s).

Three formats, told apart by their first line:

- the generic point CSV, ``time_s,x_mm,y_mm,z_mm``
  (:func:`spm_opt.verify.motion_capture.read_capture_csv`; empty x, y, z: a lost frame);
- the generic pose CSV, ``time_s,m00,m01,...,m33``: a 4×4 homogeneous pose per row, row
  by row, its translation in mm (the marker's position); empty cells: a lost frame;
- OptiTrack Motive's CSV export: a first line of ``key,value`` pairs beginning with
  ``Format Version`` and including ``Length Units``, then header rows whose first cells
  are ``Type`` (blank in older exports), ``Name``, ``ID``, the kind of each column
  (``Rotation``, ``Position``, ``Mean Marker Error``) and ``Frame,Time (Seconds),X,Y,Z...``,
  then one row per frame; empty cells are frames a body was lost in. The layout follows
  OptiTrack's documentation of the export; check it against a real export of your Motive
  version before relying on it.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.verify.motion_capture import (
    CAPTURE_COLUMNS,
    MarkerTrack,
    number_cell,
    read_capture_csv,
)

MM = 1e-3
POSE_COLUMNS = ("time_s", *(f"m{i}{j}" for i in range(4) for j in range(4)))
MOTIVE_UNITS = {"Meters": 1.0, "Centimeters": 1e-2, "Millimeters": 1e-3}
ORTHONORMAL_TOLERANCE = 1e-3
FORMATS = (
    "time_s,x_mm,y_mm,z_mm (points), time_s,m00,...,m33 (4x4 poses, mm) or an OptiTrack "
    "Motive CSV export"
)


def read_tracker_file(path: str | Path, body: str | None = None) -> MarkerTrack:
    """The marker's track in a tracker's export (see the module's docstring); ``body``
    names the rigid body or marker of a Motive export (default: its only rigid body).

    Raises
    ------
    InputError
        One line naming the file and what is wrong: an unknown format, a missing or
        unreadable cell, a pose that is not rigid, unknown length units, a body that is
        not in the file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"--tracker {path}: no such file")
    with path.open(newline="", encoding="utf-8", errors="replace") as file:
        first = file.readline().strip().lstrip("\ufeff")
    if first == ",".join(CAPTURE_COLUMNS):
        return read_capture_csv(path)
    if first == ",".join(POSE_COLUMNS):
        return _read_poses(path)
    if first.startswith("Format Version,"):
        return _read_motive(path, body)
    raise InputError(f"{path}: line 1 is {first[:60]!r}; expected {FORMATS}")


def point_csv_text(times_s: np.ndarray, points_m: np.ndarray) -> str:
    """The generic point CSV's text of a recording: times (k,), s; positions (k, 3), m,
    NaN rows written as lost frames (empty cells)."""
    lines = [",".join(CAPTURE_COLUMNS)]
    for t, p in zip(times_s, np.asarray(points_m) / MM, strict=True):
        cells = ",,," if np.isnan(p).any() else f",{p[0]:.4f},{p[1]:.4f},{p[2]:.4f}"
        lines.append(f"{t:.6f}{cells}")
    return "\n".join(lines) + "\n"


def _track(path: Path, times: list[float], points: list[list[float]], lost: list[int]):
    if not points:
        raise InputError(f"{path}: no frame with the marker ({len(lost)} lost)")
    order = np.argsort(times, kind="stable")
    times_array = np.asarray(times)[order]
    if np.any(np.diff(times_array) <= 0.0):
        raise InputError(f"{path}: two frames at the same time; times must increase")
    return MarkerTrack(times_array, np.asarray(points)[order].reshape(-1, 3), tuple(lost))


def _read_poses(path: Path) -> MarkerTrack:
    times, points, lost = [], [], []
    with path.open(newline="", encoding="utf-8", errors="replace") as file:
        for line, cells in enumerate(csv.reader(file), start=1):
            if line == 1 or not any(c.strip() for c in cells):
                continue
            if len(cells) != len(POSE_COLUMNS):
                raise InputError(
                    f"{path}: line {line}: {len(cells)} cells; expected {len(POSE_COLUMNS)}"
                )
            if not any(c.strip() for c in cells[1:]):
                lost.append(line)
                continue
            values = [
                number_cell(path, line, c, t) for c, t in zip(POSE_COLUMNS, cells, strict=True)
            ]
            matrix = np.asarray(values[1:]).reshape(4, 4)
            rotation = matrix[:3, :3]
            rigid = np.allclose(matrix[3], [0, 0, 0, 1]) and np.allclose(
                rotation.T @ rotation, np.eye(3), atol=ORTHONORMAL_TOLERANCE
            )
            if not rigid:
                raise InputError(
                    f"{path}: line {line}: not a rigid pose (last row 0 0 0 1 and an "
                    f"orthonormal rotation within {ORTHONORMAL_TOLERANCE:g} expected)"
                )
            times.append(values[0])
            points.append((matrix[:3, 3] * MM).tolist())
    return _track(path, times, points, lost)


def _read_motive(path: Path, body: str | None) -> MarkerTrack:
    with path.open(newline="", encoding="utf-8", errors="replace") as file:
        rows = list(csv.reader(file))
    settings = dict(zip(rows[0][0::2], rows[0][1::2], strict=False))
    units = settings.get("Length Units")
    if units not in MOTIVE_UNITS:
        raise InputError(
            f"{path}: Length Units = {units!r}; expected one of {', '.join(MOTIVE_UNITS)}"
        )
    scale = MOTIVE_UNITS[units]
    heading = next((i for i, r in enumerate(rows) if r[:2] == ["Frame", "Time (Seconds)"]), None)
    if heading is None or heading < 3:
        raise InputError(f"{path}: no 'Frame,Time (Seconds),...' header row; expected {FORMATS}")
    kinds, names = rows[heading - 1], rows[heading - 3]
    types = rows[heading - 4] if heading >= 4 else [""] * len(names)
    position = [i for i, k in enumerate(kinds) if k == "Position"]
    bodies = list(dict.fromkeys(names[i] for i in position))
    if body is None:
        rigid = list(
            dict.fromkeys(
                names[i] for i in position if i < len(types) and types[i] in ("Rigid Body", "")
            )
        )
        if len(rigid) != 1:
            raise InputError(
                f"{path}: {len(rigid)} rigid bodies; name one with --body (in the file: "
                f"{', '.join(bodies) or 'none'})"
            )
        body = rigid[0]
    columns = [i for i in position if names[i] == body]
    if len(columns) != 3:
        raise InputError(
            f"--body {body!r}: not in {path} (its bodies and markers: {', '.join(bodies)})"
        )
    times, points, lost = [], [], []
    for line, cells in enumerate(rows[heading + 1 :], start=heading + 2):
        if not any(c.strip() for c in cells):
            continue
        values = [cells[i].strip() if i < len(cells) else "" for i in columns]
        if not all(values):
            lost.append(line)
            continue
        times.append(number_cell(path, line, "Time (Seconds)", cells[1]))
        points.append([number_cell(path, line, body, v) * scale for v in values])
    return _track(path, times, points, lost)
