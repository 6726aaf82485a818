"""3D Slicer's markups files (``.mrk.json``): the flap's points placed on the skull in the
image, read to RAS millimetres, and written the way Slicer writes them.

```json
{"@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/...",
 "markups": [{"type": "ClosedCurve", "coordinateSystem": "LPS", "coordinateUnits": "mm",
              "controlPoints": [{"id": "1", "label": "F-1", "position": [-12.1, 30.4, 85.0],
                                 "positionStatus": "defined", ...}, ...]}]}
```

A file holds one markup: a point list (Fiducial) or a curve, open (Curve) or closed
(ClosedCurve). Its points are in LPS (when ``coordinateSystem`` is absent) or RAS, in mm
(when ``coordinateUnits`` is absent) or µm; the points not placed (``positionStatus``
"undefined" or "preview") are skipped.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.files import write_atomically
from spm_opt.base.input_limits import decode_text, excerpt, read_bytes
from spm_opt.skull.frames import to_ras

MAX_MARKUPS_BYTES = 10 << 20
"""Largest markups file, bytes (10 MiB; Slicer writes about 600 bytes a point)."""
SCHEMA = (
    "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/"
    "Resources/Schema/markups-schema-v1.0.3.json#"
)
"""The schema :func:`write_markups` names (Slicer 5's)."""
TYPES = {"Fiducial": False, "Curve": False, "ClosedCurve": True}
"""The markup types read, and whether each is closed."""
_ALL_TYPES = ("Fiducial", "Line", "Angle", "Curve", "ClosedCurve", "Plane", "ROI")
_UNITS_MM = {"mm": 1.0, "um": 1e-3}
_STATUSES = ("undefined", "preview", "defined")
_KIND = "a 3D Slicer markups file (.mrk.json)"


@dataclass(frozen=True)
class Markups:
    """The placed points of a markups file.

    Attributes
    ----------
    labels : tuple of str
        Each point's label (``P{i+1}`` for a point ``i`` of the file without one), unique.
    points_ras_mm : ndarray (n, 3)
        The points in the image's RAS coordinates, mm.
    closed : bool
        Whether the markup is a ClosedCurve.
    kind : str
        The markup's type: "Fiducial", "Curve" or "ClosedCurve".
    source : str
        The file read.
    """

    labels: tuple[str, ...]
    points_ras_mm: np.ndarray
    closed: bool
    kind: str
    source: str


def read_markups(path: str | Path) -> Markups:
    """The one markup of the Slicer markups file at ``path``, its points in RAS mm.

    Raises InputError (one line starting with the file's path) for a file larger than
    :data:`MAX_MARKUPS_BYTES`, not JSON, without exactly one markup, of a type other than
    Fiducial, Curve and ClosedCurve, in an unknown frame or unit, or with fewer than two
    placed points, a position that is not three finite numbers or labels used twice.
    """
    path = Path(path)
    text = decode_text(read_bytes(path, _KIND, MAX_MARKUPS_BYTES), path, _KIND)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as error:  # JSONDecodeError, a huge integer, nesting
        line = (str(error).splitlines() or [type(error).__name__])[0][:120]
        raise InputError(f"{path}: not JSON ({line}); expected {_KIND}") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: {excerpt(data)}: expected a JSON object with a markups list")
    markups = data.get("markups")
    if not isinstance(markups, list):
        raise InputError(f"{path}: markups = {excerpt(markups)}: expected a list of markups")
    if len(markups) != 1:
        raise InputError(
            f"{path}: markups holds {len(markups)} markups; expected one (the flap's points): "
            + ("place a point list or a curve" if not markups else "keep one, remove the others")
        )
    markup = markups[0]
    if not isinstance(markup, dict):
        raise InputError(f"{path}: markups[0] = {excerpt(markup)}: expected a JSON object")
    kind = _choice(path, markup, "type", None, tuple(TYPES))
    frame = _choice(path, markup, "coordinateSystem", "LPS", ("LPS", "RAS"))
    units = _choice(path, markup, "coordinateUnits", "mm", tuple(_UNITS_MM))
    labels, points = _placed_points(path, markup.get("controlPoints", []))
    return Markups(
        labels=labels,
        points_ras_mm=to_ras(points * _UNITS_MM[units], frame),
        closed=TYPES[kind],
        kind=kind,
        source=str(path),
    )


def _choice(
    path: Path, markup: dict, key: str, default: str | None, allowed: tuple[str, ...]
) -> str:
    """The markup's string ``key``, one of ``allowed`` (``default`` when absent)."""
    value = markup.get(key, default)
    if value not in allowed:
        known = key == "type" and value in _ALL_TYPES
        raise InputError(
            f"{path}: markups[0].{key} = {excerpt(value)}: "
            + ("this markup type is not read; " if known else "")
            + "expected "
            + ", ".join(repr(choice) for choice in allowed)
        )
    return value


def _placed_points(path: Path, control_points: object) -> tuple[tuple[str, ...], np.ndarray]:
    """The labels and positions (n, 3) of the placed points, in the file's frame and
    units."""
    field = f"{path}: markups[0].controlPoints"
    if not isinstance(control_points, list):
        raise InputError(f"{field} = {excerpt(control_points)}: expected a list of points")
    labels: list[str] = []
    positions: list[list[float]] = []
    for index, point in enumerate(control_points):
        if not isinstance(point, dict):
            raise InputError(f"{field}[{index}] = {excerpt(point)}: expected a JSON object")
        status = point.get("positionStatus", "defined")
        if status not in _STATUSES:
            raise InputError(
                f"{field}[{index}].positionStatus = {excerpt(status)}: expected "
                + ", ".join(repr(s) for s in _STATUSES)
            )
        if status != "defined":
            continue
        label = point.get("label") or f"P{index + 1}"
        if not isinstance(label, str):
            raise InputError(f"{field}[{index}].label = {excerpt(label)}: expected a string")
        if label in labels:
            raise InputError(
                f"{field}[{index}].label = {excerpt(label)}: used by an earlier point; "
                "the labels must be unique"
            )
        labels.append(label)
        positions.append(_position(point.get("position"), f"{field}[{index}] ({label!r})"))
    if not positions:
        raise InputError(
            f"{field}: no placed point (positionStatus 'defined'); expected at least 2"
        )
    if len(positions) < 2:
        raise InputError(f"{field}: 1 placed point ({labels[0]!r}); expected at least 2")
    return tuple(labels), np.array(positions)


def _position(value: object, field: str) -> list[float]:
    """A point's ``position``: three finite numbers."""
    numbers = (
        [_finite(item) for item in value] if isinstance(value, list) and len(value) == 3 else []
    )
    if len(numbers) != 3 or None in numbers:
        raise InputError(
            f"{field}.position = {excerpt(value)}: expected 3 finite numbers [x, y, z]"
        )
    return numbers


def _finite(value: object) -> float | None:
    """``value`` as a finite float, or None when it is not a finite number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        number = float(value)
    except OverflowError:  # an integer beyond a float's range
        return None
    return number if math.isfinite(number) else None


def write_markups(
    path: str | Path,
    labels: tuple[str, ...] | list[str],
    points_mm: np.ndarray,
    frame: str = "LPS",
    closed: bool = True,
) -> None:
    """Write points as a Slicer markups file, atomically: :func:`markups_text` at ``path``
    (a ``.mrk.json`` file)."""
    write_atomically({Path(path): markups_text(labels, points_mm, frame, closed)})


def markups_text(
    labels: tuple[str, ...] | list[str],
    points_mm: np.ndarray,
    frame: str = "LPS",
    closed: bool = True,
) -> str:
    """The text of a Slicer markups file holding points as a ClosedCurve (a Curve when not
    ``closed``).

    Parameters
    ----------
    labels : sequence of str
        The points' labels, unique.
    points_mm : ndarray (n, 3)
        The points in the image's RAS coordinates, mm.
    frame : str
        The file's ``coordinateSystem``, "LPS" (Slicer's default) or "RAS"; the points are
        turned to it.
    """
    points = to_ras(np.asarray(points_mm, dtype=float).reshape(-1, 3), frame)
    if len(labels) != len(points) or len(set(labels)) != len(labels):
        raise ValueError("markups_text: expected one unique label a point")
    orientation = np.diag(to_ras(np.ones(3), frame)).ravel().tolist()
    control_points = [
        {
            "id": str(index + 1),
            "label": label,
            "description": "",
            "associatedNodeID": "",
            "position": point.tolist(),
            "orientation": orientation,
            "selected": True,
            "locked": False,
            "visibility": True,
            "positionStatus": "defined",
        }
        for index, (label, point) in enumerate(zip(labels, points, strict=True))
    ]
    markup = {
        "type": "ClosedCurve" if closed else "Curve",
        "coordinateSystem": frame,
        "coordinateUnits": "mm",
        "locked": False,
        "fixedNumberOfControlPoints": False,
        "labelFormat": "%N-%d",
        "lastUsedControlPointNumber": len(points),
        "controlPoints": control_points,
        "measurements": [],
    }
    return json.dumps({"@schema": SCHEMA, "markups": [markup]}, indent=4) + "\n"
