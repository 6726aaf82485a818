"""Motion-capture verification of the platform's path (paper Section 6, Figs. 22–26).

The paper measures 8 reference landmarks, whose positions ᴹρ_i in the manipulator frame M
are known, with a tracked stylus in the camera frame C, finds the rigid transform ᴹ_C T
that takes C to M (RMS error 0.587 mm), tracks an IR marker on the platform during the
motion, maps its path to M and reports 0.731 mm between the centroids of the tracked and
the desired paths. This module does each step:

- :func:`rigid_registration`: ᴹ_C T by least squares (proper rotation, no scale; the
  fit of :mod:`spm_opt.model.rigid`), with the residual RMS over the landmark pairs, the
  paper's "RMS error"; :func:`to_manipulator_frame` maps points with it;
- :func:`path_deviation`: the paper's centroid distance, and the RMS and maximum
  closest-point distance from the tracked points to the desired path (a polyline);
- :func:`synthetic_capture`: a seeded stand-in for the cameras, so the pipeline runs
  without them;
- :func:`reference_landmarks`: 8 assumed landmark positions (the paper's are not published);
- :func:`read_capture_csv`, :func:`read_landmarks_csv`: real captures from CSV files.

SI inside (m, s); mm only on disk, in the fields of :class:`PathDeviation` and in the
:class:`~spm_opt.model.rigid.Registration` (the landmarks are converted to mm for the fit).

What RMS error to expect: with isotropic Gaussian noise of σ per coordinate on the
measured landmarks (and σ_M on the model positions), the N residuals keep 3N − 6 of the
3N noise degrees of freedom (a rigid motion absorbs 6), so
E[RMS²] = 3 (σ² + σ_M²) (N − 2) / N. For N = 8 the RMS is about 1.5 σ: the paper's
0.587 mm means σ ≈ 0.39 mm per coordinate.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.linalg import svd
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt
from spm_opt.model.params import MM, Robot
from spm_opt.model.rigid import Registration, apply, best_rigid_fit

__all__ = [
    "CAPTURE_COLUMNS",
    "LANDMARK_COLUMNS",
    "Capture",
    "MarkerTrack",
    "PathDeviation",
    "closest_point_distances",
    "path_deviation",
    "read_capture_csv",
    "read_landmarks_csv",
    "reference_landmarks",
    "rigid_registration",
    "synthetic_capture",
    "to_manipulator_frame",
]

CAPTURE_COLUMNS = ("time_s", "x_mm", "y_mm", "z_mm")
LANDMARK_COLUMNS = ("name", "x_mm", "y_mm", "z_mm")

# Relative size of the second singular value of centred points below which they count as
# collinear (the rotation about their line is then undetermined).
_COLLINEAR_TOLERANCE = 1e-6


# --- input checks --------------------------------------------------------------------


def _points(name: str, value: object, *, min_rows: int = 1, single: bool = False) -> np.ndarray:
    """``value`` as a finite float array of shape (N, 3), N >= min_rows (or (3,) if single)."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected an array of shape (N, 3) of numbers") from None
    if not (array.ndim == 2 and array.shape[1] == 3) and not (single and array.shape == (3,)):
        raise InputError(f"{name}: expected shape (N, 3), got {array.shape}")
    if array.ndim == 2 and array.shape[0] < min_rows:
        raise InputError(f"{name}: {array.shape[0]} points; expected at least {min_rows}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: expected finite numbers (no NaN or inf)")
    return array


def _times(name: str, value: object, n: int) -> np.ndarray:
    try:
        times = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected an array of shape ({n},) of times in s") from None
    if times.shape != (n,):
        raise InputError(f"{name}: expected shape ({n},) like the marker path, got {times.shape}")
    if not np.all(np.isfinite(times)):
        raise InputError(f"{name}: expected finite numbers (no NaN or inf)")
    if np.any(np.diff(times) <= 0.0):
        raise InputError(f"{name}: times must increase strictly")
    return times


def _check_not_collinear(name: str, points: np.ndarray) -> None:
    singular = svd(points - points.mean(axis=0), compute_uv=False)
    if singular[0] == 0.0:
        raise InputError(f"{name}: all points coincide; expected at least 3 not on one line")
    if singular[1] <= _COLLINEAR_TOLERANCE * singular[0]:
        raise InputError(f"{name}: the points are collinear; expected at least 3 not on one line")


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.flags.writeable = False
    return array


# --- registration --------------------------------------------------------------------


def rigid_registration(camera_points: np.ndarray, model_points: np.ndarray) -> Registration:
    """The rigid transform taking landmarks measured in C onto their known positions in M.

    Least squares over the pairs, min Σ |R c_i + t − m_i|² with R a proper rotation and no
    scale (:func:`spm_opt.model.rigid.best_rigid_fit`, on the points converted to mm).

    Parameters
    ----------
    camera_points : ndarray, shape (N, 3), m
        The landmarks as measured in the camera frame C (ᶜρ_i), N >= 3.
    model_points : ndarray, shape (N, 3), m
        The same landmarks' known positions in the manipulator frame M (ᴹρ_i), same order.

    Returns
    -------
    Registration
        In mm: ᴹ_C T with its translation in mm, the residuals and their RMS (the paper's
        "RMS error") in mm.

    Raises
    ------
    InputError
        Wrong shapes, fewer than 3 pairs, NaN or inf, different numbers of points, or
        landmarks on one line (which leave the rotation about that line undetermined).
    """
    camera = _points("camera_points", camera_points, min_rows=3)
    model = _points("model_points", model_points, min_rows=3)
    if model.shape != camera.shape:
        raise InputError(
            f"model_points: {model.shape[0]} points; expected {camera.shape[0]}, one for "
            "each of camera_points"
        )
    _check_not_collinear("camera_points", camera)
    _check_not_collinear("model_points", model)
    return best_rigid_fit(camera / MM, model / MM)


def to_manipulator_frame(registration: Registration, points_c: np.ndarray) -> np.ndarray:
    """Points in the camera frame C, shape (N, 3) or (3,), m, mapped to M by ``registration``
    (from :func:`rigid_registration`); same shape, m."""
    points = _points("points_c", points_c, single=True)
    return apply(registration.matrix_mm, points / MM) * MM


# --- deviation between a tracked and a desired path ------------------------------------


@dataclass(frozen=True)
class PathDeviation:
    """How far a tracked path lies from the desired one, in mm (for people).

    Attributes
    ----------
    centroid_distance_mm : float
        Distance between the centroids of the two point sets (the paper's 0.731 mm).
    rms_distance_mm, max_distance_mm : float
        RMS and maximum over the tracked points of the distance to the closest point of
        the desired path, taken as a polyline.
    """

    centroid_distance_mm: float
    rms_distance_mm: float
    max_distance_mm: float

    def to_dict(self) -> dict[str, float]:
        """The fields by name."""
        return {
            "centroid_distance_mm": self.centroid_distance_mm,
            "rms_distance_mm": self.rms_distance_mm,
            "max_distance_mm": self.max_distance_mm,
        }


def _segment_distances(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Row by row, the distance from points (K, 3) to segments [starts, ends] (K, 3)."""
    direction = ends - starts
    length2 = np.einsum("ij,ij->i", direction, direction)
    along = np.einsum("ij,ij->i", points - starts, direction)
    fraction = np.clip(np.divide(along, length2, out=np.zeros_like(along), where=length2 > 0), 0, 1)
    return np.linalg.norm(points - starts - fraction[:, None] * direction, axis=1)


def closest_point_distances(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance from each point to the closest point of a polyline.

    Exact (point-to-segment distances), with KD-trees to shortlist the segments: the
    segments are cut into pieces no longer than h (about the typical segment length or
    the typical distance of the points to the path); a point at distance at most u from
    the path (u: its distance to the nearest piece midpoint) can only be closest to a
    piece whose midpoint lies within u + h/2 of it.

    Parameters
    ----------
    points : ndarray, shape (N, 3), m
    path : ndarray, shape (M, 3), m
        The polyline's vertices in order, M >= 1 (repeated vertices are allowed).

    Returns
    -------
    ndarray, shape (N,), m
    """
    points = _points("points", points)
    path = _points("path", path)
    vertex_distance, _ = cKDTree(path).query(points)
    if len(path) == 1:
        return vertex_distance
    starts, ends = path[:-1], path[1:]
    lengths = np.linalg.norm(ends - starts, axis=1)
    h = max(float(np.median(lengths)), float(lengths.sum()) / len(lengths))
    h = max(h, float(np.median(vertex_distance)))
    if h == 0.0:  # every vertex is the same point
        return vertex_distance

    # Cut segment i into n_i equal pieces; at most 2 (M - 1) pieces in all.
    pieces = np.maximum(1, np.ceil(lengths / h)).astype(int)
    segment = np.repeat(np.arange(len(lengths)), pieces)
    first = np.cumsum(pieces) - pieces
    index = np.arange(len(segment)) - first[segment]
    direction = (ends - starts)[segment]
    piece_starts = starts[segment] + (index / pieces[segment])[:, None] * direction
    piece_ends = starts[segment] + ((index + 1) / pieces[segment])[:, None] * direction
    middles = 0.5 * (piece_starts + piece_ends)
    half = 0.5 * float(np.linalg.norm(piece_ends - piece_starts, axis=1).max())

    tree = cKDTree(middles)
    middle_distance, _ = tree.query(points)
    bound = np.minimum(vertex_distance, middle_distance)
    radius = bound + half + 1e-9 * (bound + half) + 1e-15
    result = np.array(vertex_distance)
    chunk = 4096
    for begin in range(0, len(points), chunk):
        stop = min(begin + chunk, len(points))
        candidates = tree.query_ball_point(points[begin:stop], radius[begin:stop])
        counts = np.fromiter((len(c) for c in candidates), dtype=int, count=len(candidates))
        owner = np.repeat(np.arange(begin, stop), counts)
        which = np.concatenate([np.asarray(c, dtype=int) for c in candidates])
        distance = _segment_distances(points[owner], piece_starts[which], piece_ends[which])
        np.minimum.at(result, owner, distance)
    return result


def path_deviation(tracked_m: np.ndarray, desired_m: np.ndarray) -> PathDeviation:
    """Deviation of a tracked path from the desired one, both in the manipulator frame.

    Parameters
    ----------
    tracked_m : ndarray, shape (N, 3), m
        The marker's positions as tracked and mapped to M (occluded samples removed).
    desired_m : ndarray, shape (M, 3), m
        The desired path's points in order, treated as a polyline for the closest-point
        distances.

    Returns
    -------
    PathDeviation

    Notes
    -----
    The centroid distance is the paper's measure. It depends on how each path is sampled
    (a path sampled evenly in time weighs slow stretches more) and offsets in opposite
    directions cancel in it, so a small centroid distance alone does not show close
    tracking; the closest-point RMS and maximum do not have these weaknesses (but ignore
    timing: a marker late along the path is not penalised).
    """
    tracked = _points("tracked_m", tracked_m)
    desired = _points("desired_m", desired_m)
    centroid = float(np.linalg.norm(tracked.mean(axis=0) - desired.mean(axis=0)))
    distances = closest_point_distances(tracked, desired)
    return PathDeviation(
        centroid_distance_mm=centroid / MM,
        rms_distance_mm=float(np.sqrt(np.mean(distances**2))) / MM,
        max_distance_mm=float(distances.max()) / MM,
    )


# --- a synthetic capture -----------------------------------------------------------------


@dataclass(frozen=True)
class Capture:
    """One motion capture: landmarks measured with the stylus and the marker's path, in C.

    Attributes
    ----------
    landmarks_c : ndarray, shape (N, 3), m
        The landmarks as measured in the camera frame.
    marker_times_s : ndarray, shape (K,), s
    marker_c : ndarray, shape (K, 3), m
        The platform marker's path in the camera frame.
    noise_std_m : float, m
        The standard deviation per coordinate of the noise added to every measured point.
    true_rotation : ndarray, shape (3, 3)
    true_translation : ndarray, shape (3,), m
        The transform from C to M the capture was made with (p_M = R p_C + t): known only
        because the capture is synthetic; for tests.
    """

    landmarks_c: np.ndarray
    marker_times_s: np.ndarray
    marker_c: np.ndarray
    noise_std_m: float
    true_rotation: np.ndarray
    true_translation: np.ndarray


def synthetic_capture(
    landmarks_m: np.ndarray,
    marker_times_s: np.ndarray,
    marker_m: np.ndarray,
    *,
    rng: int | np.random.Generator = 0,
    noise_std_m: float | tuple[float, float] = (0.3 * MM, 0.6 * MM),
    max_translation_m: float = 1.0,
) -> Capture:
    """What the cameras would report for known landmarks and a known marker path.

    Draws an unknown camera placement (a uniformly random rotation and a translation
    uniform in the ball of radius ``max_translation_m``), expresses the landmarks and the
    marker path in the camera frame and adds isotropic Gaussian noise to every point.

    Parameters
    ----------
    landmarks_m : ndarray, shape (N, 3), m
        Landmark positions in M (e.g. :func:`reference_landmarks`).
    marker_times_s : ndarray, shape (K,), s
        Strictly increasing.
    marker_m : ndarray, shape (K, 3), m
        The marker's true path in M.
    rng : int or numpy.random.Generator
        Seed or generator; the same seed gives the same capture.
    noise_std_m : float or (float, float), m
        Standard deviation of the noise per coordinate, or a range from which one value is
        drawn uniformly for this capture (default 0.3–0.6 mm).
    max_translation_m : float, m

    Returns
    -------
    Capture
    """
    landmarks = _points("landmarks_m", landmarks_m)
    marker = _points("marker_m", marker_m)
    times = _times("marker_times_s", marker_times_s, len(marker))
    try:
        bounds = np.broadcast_to(np.asarray(noise_std_m, dtype=float), (2,))
    except (TypeError, ValueError):
        bounds = np.array([math.nan, math.nan])
    low, high = float(bounds[0]), float(bounds[1])
    if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
        raise InputError(
            f"noise_std_m = {excerpt(noise_std_m)}: expected a standard deviation >= 0 in m or a "
            "range (low, high) with 0 <= low <= high"
        )
    if not (math.isfinite(max_translation_m) and max_translation_m >= 0.0):
        raise InputError(
            f"max_translation_m = {excerpt(max_translation_m)}: expected a distance >= 0"
        )

    generator = np.random.default_rng(rng)
    rotation = Rotation.random(random_state=generator).as_matrix()
    direction = generator.standard_normal(3)
    direction /= np.linalg.norm(direction)
    translation = direction * max_translation_m * generator.uniform() ** (1.0 / 3.0)
    sigma = float(generator.uniform(low, high)) if high > low else float(low)

    def to_camera(points_m: np.ndarray) -> np.ndarray:
        # p_M = R p_C + t  ⇔  p_C = Rᵀ (p_M − t); row-wise (p_M − t) R.
        exact = (points_m - translation) @ rotation
        return exact + sigma * generator.standard_normal(exact.shape)

    return Capture(
        landmarks_c=_frozen(to_camera(landmarks)),
        marker_times_s=_frozen(times),
        marker_c=_frozen(to_camera(marker)),
        noise_std_m=sigma,
        true_rotation=_frozen(rotation),
        true_translation=_frozen(translation),
    )


def reference_landmarks(robot_or_radius: Robot | float) -> np.ndarray:
    """8 assumed reference landmark positions in M (the paper's are not published).

    ASSUMPTION: the paper's landmark markers (Fig. 22) sit on the robot's base around the
    isocenter. Here they are placed on a ring around the vertical axis through the
    isocenter, at azimuths 22.5° + k·45° (between the arcs' pivots on the x and y axes),
    alternately in the isocenter plane (z = 0) and 0.2 ring radii below it, so they are
    not coplanar and surround the working volume in plan view.

    Parameters
    ----------
    robot_or_radius : Robot or float
        A robot (ring radius: its upper arc's rail radius + 30 mm, 190 mm for the
        prototype) or the ring radius itself, m.

    Returns
    -------
    ndarray, shape (8, 3), m
    """
    if isinstance(robot_or_radius, Robot):
        radius = robot_or_radius.upper_arc.rail_radius + 30.0 * MM
    else:
        radius = float(robot_or_radius)
    if not (math.isfinite(radius) and radius > 0.0):
        raise InputError(
            f"robot_or_radius = {excerpt(robot_or_radius)}: expected a radius > 0 in m"
        )
    azimuth = np.deg2rad(22.5 + 45.0 * np.arange(8))
    height = np.where(np.arange(8) % 2 == 0, 0.0, -0.2 * radius)
    return np.column_stack([radius * np.cos(azimuth), radius * np.sin(azimuth), height])


# --- capture files ---------------------------------------------------------------------


class MarkerTrack(tuple[np.ndarray, np.ndarray]):
    """The pair (times_s, points_m) read from a capture file, and the occluded lines.

    Unpacks as a pair, ``times, points = read_capture_csv(path)``; ``occluded_lines``
    holds the file's line numbers (1-based) skipped because the marker was missing.
    """

    occluded_lines: tuple[int, ...]

    def __new__(
        cls, times_s: np.ndarray, points_m: np.ndarray, occluded_lines: tuple[int, ...]
    ) -> MarkerTrack:
        track = super().__new__(cls, (times_s, points_m))
        track.occluded_lines = tuple(occluded_lines)
        return track

    def __getnewargs__(self) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:  # for copy, pickle
        return self[0], self[1], self.occluded_lines

    @property
    def times_s(self) -> np.ndarray:
        """Shape (K,), s."""
        return self[0]

    @property
    def points_m(self) -> np.ndarray:
        """Shape (K, 3), m."""
        return self[1]

    @property
    def n_occluded(self) -> int:
        """How many lines were skipped because the marker was missing."""
        return len(self.occluded_lines)


def _rows(path: Path, columns: tuple[str, ...]) -> list[tuple[int, list[str]]]:
    """(line number, stripped cells) of each non-blank data row after the exact header."""
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle)
            rows = [(reader.line_num, [c.strip() for c in row]) for row in reader if row]
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise InputError(f"{path}: cannot be read ({error})") from None
    expected = ",".join(columns)
    if not rows:
        raise InputError(f"{path}: empty file; expected the header {expected}")
    line, header = rows[0]
    if tuple(header) != columns:
        missing = [c for c in columns if c not in header]
        found = f"column {missing[0]} is missing" if missing else f"header is {','.join(header)!r}"
        raise InputError(f"{path}: line {line}: {found}; expected the header {expected}")
    for line, cells in rows[1:]:
        if len(cells) != len(columns):
            what = "missing" if len(cells) < len(columns) else "has extra cells after it"
            column = columns[min(len(cells), len(columns) - 1)]
            raise InputError(
                f"{path}: line {line}, column {column} {what}; expected {len(columns)} "
                f"cells ({expected})"
            )
    return rows[1:]


def number_cell(path: Path, line: int, column: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise InputError(f"{path}: line {line}, column {column} = {text!r}: expected a number")
    return value


def read_capture_csv(path: str | Path) -> MarkerTrack:
    """Read a marker path exported from the motion-capture software.

    Format: a header row ``time_s,x_mm,y_mm,z_mm`` (exactly these columns, in this order),
    then one row per frame: time in s, position in mm (in whatever frame the export
    uses, normally C). A row whose x, y and z cells are all empty is a frame in which the
    marker was occluded: it is skipped and counted. Blank lines are ignored.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    MarkerTrack
        Unpacks as (times_s, points_m): times, shape (K,), s, and positions, shape (K, 3),
        m; ``.occluded_lines`` lists the skipped lines.

    Raises
    ------
    InputError
        Naming the file, line and column: a wrong header, a missing cell, a value that is
        not a finite number (including an empty time, or only some of x, y, z empty),
        times that do not increase strictly, or no frame with the marker.
    """
    path = Path(path)
    times: list[float] = []
    points: list[list[float]] = []
    occluded: list[int] = []
    previous: tuple[int, float] | None = None
    for line, cells in _rows(path, CAPTURE_COLUMNS):
        if not any(cells[1:]):
            occluded.append(line)
            continue
        time = number_cell(path, line, "time_s", cells[0])
        if previous is not None and time <= previous[1]:
            raise InputError(
                f"{path}: line {line}, column time_s = {cells[0]!r}: times must increase "
                f"strictly (line {previous[0]} has {previous[1]:g})"
            )
        previous = (line, time)
        times.append(time)
        points.append(
            [
                number_cell(path, line, c, t) * MM
                for c, t in zip(CAPTURE_COLUMNS[1:], cells[1:], strict=True)
            ]
        )
    if not points:
        raise InputError(
            f"{path}: no frame with the marker ({len(occluded)} occluded); expected at least 1"
        )
    return MarkerTrack(np.array(times), np.array(points).reshape(-1, 3), tuple(occluded))


def read_landmarks_csv(path: str | Path) -> tuple[tuple[str, ...], np.ndarray]:
    """Read landmark positions: header ``name,x_mm,y_mm,z_mm``, one landmark per row.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    names : tuple of str
        Non-empty and distinct.
    points : ndarray, shape (N, 3), m

    Raises
    ------
    InputError
        Naming the file, line and column: a wrong header, a missing cell, an empty or
        repeated name, a value that is not a finite number, or no landmark.
    """
    path = Path(path)
    names: list[str] = []
    points: list[list[float]] = []
    for line, cells in _rows(path, LANDMARK_COLUMNS):
        name = cells[0]
        if not name:
            raise InputError(f"{path}: line {line}, column name is empty; expected a name")
        if name in names:
            raise InputError(f"{path}: line {line}, column name = {name!r}: repeated name")
        names.append(name)
        points.append(
            [
                number_cell(path, line, c, t) * MM
                for c, t in zip(LANDMARK_COLUMNS[1:], cells[1:], strict=True)
            ]
        )
    if not points:
        raise InputError(f"{path}: no landmark; expected at least 1 row after the header")
    return tuple(names), np.array(points)
