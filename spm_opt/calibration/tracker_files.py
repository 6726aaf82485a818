"""A tracker's recording from the files labs export, as one marker's track (m, s).

Three formats, told apart by their first line:

- the generic point CSV, ``time_s,x_mm,y_mm,z_mm``
  (:func:`spm_opt.verify.motion_capture.read_capture_csv`; empty x, y, z: a lost frame);
- the generic pose CSV, ``time_s,m00,m01,...,m33``: a 4×4 homogeneous pose per row, row
  by row, its translation in mm (the marker's position); its last row must be 0 0 0 1 and
  its rotation proper and orthonormal within :data:`ORTHONORMAL_TOLERANCE`; empty pose
  cells: a lost frame;
- OptiTrack Motive's CSV export: line 1 ``key,value`` pairs beginning with
  ``Format Version`` and including ``Length Units`` (Meters, Centimeters or Millimeters);
  line 2 blank; header rows ``,Type,...`` (Rigid Body, Rigid Body Marker, Marker, ...),
  ``,Name,...``, ``,ID,...``, in format 1.25 (Motive 3) also ``,Parent,...``; then the
  kind of each column (``,,Rotation,...,Position,...,Mean Marker Error``) and
  ``Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,...``; then one row per frame, empty cells where a
  body was lost. The Type and Name rows are found by their labels (without labels: 4 and 3
  rows above the ``Frame`` row), the columns by the kind row and the X, Y, Z of the
  ``Frame`` row, so extra rows or columns (a TimeCode) do not move them.

What the Motive layout rests on: OptiTrack's documentation of the export
(docs.optitrack.com, "Data Export: CSV") lists the options (units, markers, rigid bodies,
rigid body markers — the expected, not the measured, positions — quality statistics,
header) but not the rows; the rows are those of real format-1.23 exports (Motive 2,
published with the pathviewr R package), and the Parent row of format 1.25 that of
third-party readers. Check it against an export of your Motive version before relying on
it.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.model.params import MM
from spm_opt.verify.motion_capture import (
    CAPTURE_COLUMNS,
    MarkerTrack,
    number_cell,
    read_capture_csv,
)

POSE_COLUMNS = ("time_s", *(f"m{i}{j}" for i in range(4) for j in range(4)))
MOTIVE_UNITS = {"Meters": 1.0, "Centimeters": 1e-2, "Millimeters": 1e-3}
MOTIVE_PREFERENCE = ("Rigid Body", "Marker", "Rigid Body Marker")
"""Which of a Motive export's columns of one name to read: a rigid body, else the measured
marker, else the rigid body's expected marker."""
ORTHONORMAL_TOLERANCE = 1e-3
FORMATS = (
    "time_s,x_mm,y_mm,z_mm (points), time_s,m00,...,m33 (4x4 poses, mm) or an OptiTrack "
    "Motive CSV export"
)


def read_tracker_file(path: str | Path, body: str | None = None) -> MarkerTrack:
    """The marker's track in a tracker's export, its format told by its first line (see
    the module's docstring).

    Parameters
    ----------
    path : str or Path
    body : str, optional
        A Motive export's rigid body or marker to read (its Name row); by default its only
        rigid body. Ignored by the other formats.

    Returns
    -------
    MarkerTrack
        Times (k,), s, strictly increasing; positions (k, 3), m; ``occluded_lines``: the
        file's lines (1-based) of the frames the marker was lost in.

    Raises
    ------
    InputError
        One line naming the file and what is wrong: an unknown format, a missing or
        unreadable cell, a pose that is not rigid, unknown length units, a body that is
        not in the file (or no ``body`` and not one rigid body), times that do not
        increase.
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


def _track(path: Path, rows: list[tuple[int, float, list[float]]], lost: list[int]) -> MarkerTrack:
    """The track of (line, time in s, point in m) rows; times must increase strictly."""
    if not rows:
        raise InputError(f"{path}: no frame with the marker ({len(lost)} lost)")
    for (previous, before, _), (line, time, _) in zip(rows, rows[1:], strict=False):
        if time <= before:
            raise InputError(
                f"{path}: line {line}: time {time:g} s; times must increase strictly "
                f"(line {previous} has {before:g} s)"
            )
    times = np.array([time for _, time, _ in rows])
    return MarkerTrack(times, np.array([p for _, _, p in rows]).reshape(-1, 3), tuple(lost))


def _check_rigid(path: Path, line: int, matrix: np.ndarray) -> None:
    """One line if a pose (4, 4) is not rigid: its last row 0 0 0 1, its rotation proper and
    orthonormal within :data:`ORTHONORMAL_TOLERANCE`."""
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-9):
        row = " ".join(f"{v:g}" for v in matrix[3])
        raise InputError(f"{path}: line {line}, columns m30-m33 = {row}; expected 0 0 0 1")
    rotation = matrix[:3, :3]
    error = float(np.max(np.abs(rotation.T @ rotation - np.eye(3))))
    if error > ORTHONORMAL_TOLERANCE:
        raise InputError(
            f"{path}: line {line}, columns m00-m22: not a rotation (|RᵀR − I| up to "
            f"{error:.3g}; at most {ORTHONORMAL_TOLERANCE:g} allowed)"
        )
    if np.linalg.det(rotation) < 0.0:
        raise InputError(
            f"{path}: line {line}, columns m00-m22: a reflection (determinant "
            f"{np.linalg.det(rotation):.3g}); expected a rotation (determinant 1)"
        )


def _read_poses(path: Path) -> MarkerTrack:
    rows, lost = [], []
    with path.open(newline="", encoding="utf-8", errors="replace") as file:
        for line, cells in enumerate(csv.reader(file), start=1):
            if line == 1 or not any(c.strip() for c in cells):
                continue
            if len(cells) != len(POSE_COLUMNS):
                raise InputError(
                    f"{path}: line {line}: {len(cells)} cells; expected {len(POSE_COLUMNS)} "
                    f"({POSE_COLUMNS[0]},{POSE_COLUMNS[1]},...,{POSE_COLUMNS[-1]})"
                )
            if not any(c.strip() for c in cells[1:]):
                lost.append(line)
                continue
            values = [
                number_cell(path, line, c, t) for c, t in zip(POSE_COLUMNS, cells, strict=True)
            ]
            matrix = np.asarray(values[1:]).reshape(4, 4)
            _check_rigid(path, line, matrix)
            rows.append((line, values[0], (matrix[:3, 3] * MM).tolist()))
    return _track(path, rows, lost)


def _motive_header(rows: list[list[str]], heading: int, label: str, above: int) -> list[str]:
    """The header row labelled ``label`` in its second cell, or the row ``above`` rows above
    the ``Frame`` row (``heading``) when no row is labelled."""
    labelled = [r for r in rows[1:heading] if len(r) > 1 and r[1].strip() == label]
    if labelled:
        return labelled[0]
    return rows[heading - above] if heading >= above + 1 else []


def _motive_columns(
    path: Path, rows: list[list[str]], heading: int, body: str | None
) -> tuple[str, list[int]]:
    """The body's name and the indices of its Position X, Y, Z columns (``heading``: the
    index of the ``Frame`` row)."""
    kinds = rows[heading - 1]
    names = _motive_header(rows, heading, "Name", 3)
    types = _motive_header(rows, heading, "Type", 4)

    def cell(row: list[str], i: int) -> str:
        return row[i].strip() if i < len(row) else ""

    groups: dict[tuple[str, str], list[int]] = {}
    for i, kind in enumerate(kinds):
        if kind.strip() == "Position" and cell(names, i):
            groups.setdefault((cell(names, i), cell(types, i)), []).append(i)
    listed = ", ".join(dict.fromkeys(name for name, _ in groups)) or "none"
    if body is None:
        rigid = [name for name, kind in groups if kind in ("Rigid Body", "")]
        if len(rigid) != 1:
            raise InputError(
                f"{path}: {len(rigid)} rigid bodies; name one with --body (its bodies and "
                f"markers: {listed})"
            )
        body = rigid[0]
    found = [kind for name, kind in groups if name == body]
    if not found:
        raise InputError(f"--body {body!r}: not in {path} (its bodies and markers: {listed})")
    kind = next((k for k in MOTIVE_PREFERENCE if k in found), found[0])
    columns = groups[(body, kind)]
    axes = [cell(rows[heading], i) for i in columns]
    if axes != ["X", "Y", "Z"]:
        raise InputError(
            f"{path}: line {heading + 1}: {body!r}'s Position columns are "
            f"{','.join(axes)}; expected X,Y,Z"
        )
    return body, columns


def _read_motive(path: Path, body: str | None) -> MarkerTrack:
    with path.open(newline="", encoding="utf-8-sig", errors="replace") as file:
        rows = list(csv.reader(file))
    settings = {k.strip(): v.strip() for k, v in zip(rows[0][0::2], rows[0][1::2], strict=False)}
    units = settings.get("Length Units")
    if units not in MOTIVE_UNITS:
        found = "no Length Units" if units is None else f"Length Units = {units!r}"
        raise InputError(f"{path}: line 1 has {found}; expected one of {', '.join(MOTIVE_UNITS)}")
    scale = MOTIVE_UNITS[units]
    heading = next(
        (
            i
            for i, r in enumerate(rows)
            if [c.strip() for c in r[:2]] == ["Frame", "Time (Seconds)"]
        ),
        None,
    )
    if heading is None or heading < 2:
        raise InputError(
            f"{path}: no header row 'Frame,Time (Seconds),...' after line 2; expected a "
            "Motive CSV export with its header rows"
        )
    body, columns = _motive_columns(path, rows, heading, body)
    points, lost = [], []
    for line, cells in enumerate(rows[heading + 1 :], start=heading + 2):
        if not any(c.strip() for c in cells):
            continue
        values = [cells[i].strip() if i < len(cells) else "" for i in columns]
        if not all(values):
            lost.append(line)
            continue
        time = number_cell(path, line, "Time (Seconds)", cells[1])
        point = [
            number_cell(path, line, f"{body} {axis}", v) * scale
            for axis, v in zip("XYZ", values, strict=True)
        ]
        points.append((line, time, point))
    return _track(path, points, lost)
