"""A problem file's skull: the ``[skull]`` table and the ``landmarks_file`` key.

```toml
landmarks_file = "flap.mrk.json"      # a 3D Slicer markups file, relative to this file
[skull]
outer_mesh = "skull_outer.stl"        # relative to this file, mm, in `frame`
inner_mesh = "skull_inner.stl"        # optional
frame = "RAS"                         # or "LPS": the meshes' frame
max_landmark_shift_mm = 5             # optional: the farthest a landmark moves onto the mesh
image_to_robot = [[1, 0, 0, 0.5], [0, 1, 0, 21.1], [0, 0, 1, -6.2], [0, 0, 0, 1]]
[skull.registration]                  # or, instead of image_to_robot:
image_fiducials_mm = [[...], ...]     # in `frame`
robot_fiducials_mm = [[...], ...]
max_fiducial_residual_mm = 2          # optional: the largest residual of the fit
```

``image_to_robot`` takes the image's RAS coordinates (mm) to the robot's frame (mm): a mesh
in LPS is turned to RAS first, so the LPS and RAS copies of one skull take the same
transform.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.fields import Table
from spm_opt.model.params import MM
from spm_opt.model.rigid import Registration, apply
from spm_opt.skull.frames import FRAMES, to_ras
from spm_opt.skull.landmark_surface import LandmarkSurface
from spm_opt.skull.markups import read_markups
from spm_opt.skull.registration import check_residuals, check_transform, fit_rigid
from spm_opt.skull.surface import Skull

MAX_LANDMARK_SHIFT_MM = 5.0
"""Default of ``[skull] max_landmark_shift_mm``: the farthest a landmark may move along its
direction from the isocenter onto the outer mesh, mm. A point placed on the bone's surface
in the image lies within a voxel or two of the mesh segmented from it (the generated
example's: within 0.00001 mm); one farther out was placed on something else (the scalp,
say), in another frame or unit, or on another skull."""
MAX_FIDUCIAL_RESIDUAL_MM = 2.0
"""Default of ``[skull.registration] max_fiducial_residual_mm``: the largest distance
allowed, mm, between a robot fiducial and its image fiducial once the fit is applied. Bone
fiducials located well give residuals of a fraction of a millimetre; a residual above 2 mm
is a fiducial located wrongly in one frame (one 20 mm off among the generated example's
four gives residuals up to 8.5 mm, RMS 6.4 mm), and every point of the cut inherits the
fit's error."""


@dataclass(frozen=True)
class SkullKeys:
    """What a problem file says of its skull, read and converted.

    Attributes
    ----------
    image_to_robot_mm : ndarray (4, 4) or None
        From the image's RAS coordinates to the robot's frame, mm.
    frame : str
        The meshes' frame, "RAS" or "LPS".
    outer, inner : trimesh.Trimesh or None
        The meshes in the robot's frame, m.
    registration : Registration or None
        The fit of the fiducials, when the transform came from them.
    field : str
        The file and the outer mesh's key, for messages.
    depth_margin : float, m
    max_landmark_shift : float, m
        The farthest a landmark may move along its direction onto the outer mesh.
    shift_field : str
        The file and that bound's key, for messages.
    """

    image_to_robot_mm: np.ndarray | None
    frame: str
    outer: object | None
    inner: object | None
    registration: Registration | None
    field: str
    depth_margin: float
    max_landmark_shift: float
    shift_field: str


def read_skull_table(table: Table, folder: Path) -> SkullKeys | None:
    """The ``[skull]`` table (None when the file has none)."""
    if not table.keys():
        return None
    frame = table.string("frame", choices=FRAMES)
    matrix, registration = _transform(table, frame)
    outer_key = table.string("outer_mesh", default="")
    inner_key = table.string("inner_mesh", default="")
    if inner_key and not outer_key:
        raise table.error("inner_mesh", inner_key, "expected an outer_mesh beside it")
    margin = table.number("depth_margin_mm", default=0.0, minimum=-20.0, maximum=20.0)
    shift = table.number(
        "max_landmark_shift_mm",
        default=MAX_LANDMARK_SHIFT_MM,
        minimum=0.0,
        exclusive_minimum=True,
    )
    table.finish()
    outer = inner = None
    if outer_key:
        from spm_opt.skull.mesh import load_mesh, to_robot

        outer = to_robot(
            load_mesh(folder / outer_key, frame, table.name("outer_mesh")), frame, matrix
        )
        if inner_key:
            inner = to_robot(
                load_mesh(folder / inner_key, frame, table.name("inner_mesh")), frame, matrix
            )
    return SkullKeys(
        matrix,
        frame,
        outer,
        inner,
        registration,
        table.name("outer_mesh"),
        margin * MM,
        shift * MM,
        table.name("max_landmark_shift_mm"),
    )


def _transform(table: Table, frame: str) -> tuple[np.ndarray, Registration | None]:
    """The image-to-robot transform (4, 4), mm, and the fiducials' fit (None for a matrix
    given as it is), refused when a fiducial's residual exceeds the table's
    ``max_fiducial_residual_mm``."""
    has_matrix, has_fiducials = table.has("image_to_robot"), table.has("registration")
    if has_matrix == has_fiducials:
        raise InputError(
            f"{table.name('image_to_robot')}: expected either image_to_robot (a 4x4 matrix, "
            f"mm) or a [{table.name('registration')}] table of fiducials, "
            + ("not both" if has_matrix else "got neither")
        )
    if has_matrix:
        return check_transform(table.raw("image_to_robot"), table.name("image_to_robot")), None
    fiducials = table.table("registration")
    image = _points(fiducials, "image_fiducials_mm")
    robot = _points(fiducials, "robot_fiducials_mm")
    largest = fiducials.number(
        "max_fiducial_residual_mm",
        default=MAX_FIDUCIAL_RESIDUAL_MM,
        minimum=0.0,
        exclusive_minimum=True,
    )
    fiducials.finish()
    registration = fit_rigid(to_ras(image, frame), robot, fiducials.name("image_fiducials_mm"))
    check_residuals(registration, largest, fiducials.name("max_fiducial_residual_mm"))
    return registration.matrix_mm, registration


def _points(table: Table, key: str) -> np.ndarray:
    """A list of 3-D points, mm."""
    value = table.raw(key)
    try:
        points = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise table.error(key, value, "expected a list of [x, y, z] points in mm") from None
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise table.error(key, value, "expected a list of [x, y, z] points in mm, all finite")
    return points


def markup_landmarks(
    path: Path, keys: SkullKeys | None, field: str
) -> tuple[tuple[str, ...], np.ndarray, bool]:
    """The landmarks of a markups file: names, points (n, 3) in the robot's frame, m, and
    whether the curve is closed."""
    if keys is None or keys.image_to_robot_mm is None:
        raise InputError(
            f"{field} = '{path.name}': a markups file is in the image's coordinates; the "
            "[skull] table must give image_to_robot or a registration"
        )
    markups = read_markups(path)
    return (
        markups.labels,
        apply(keys.image_to_robot_mm, markups.points_ras_mm) * MM,
        (markups.closed),
    )


def skull_on_mesh(
    keys: SkullKeys, names: tuple[str, ...], landmarks: np.ndarray, origin: str = ""
) -> tuple[Skull, np.ndarray]:
    """The problem's skull and its landmarks moved along their directions onto the outer
    mesh (m), each at most ``keys.max_landmark_shift``; without a mesh, the smooth surface
    through the landmarks as they are. ``origin`` names where the landmarks were read
    (a markups file), for messages."""
    registration = keys.registration
    fit = {
        "registration_rms_mm": None if registration is None else registration.rms_mm,
        "fiducial_residuals_mm": None if registration is None else registration.residuals_mm,
        "image_to_robot_mm": keys.image_to_robot_mm,
    }
    if keys.outer is None:
        return Skull(LandmarkSurface(landmarks), **fit), landmarks
    from spm_opt.skull.raycast import MeshSurface

    surface = MeshSurface(keys.outer, keys.inner)
    if not surface.contains_isocenter():
        raise InputError(
            f"{keys.field}: the isocenter (the robot's origin) lies outside the outer surface "
            "once image_to_robot is applied; check the transform and the mesh's frame"
        )
    radii = np.linalg.norm(landmarks, axis=1)
    directions = landmarks / radii[:, None]
    crossings = surface.crossings(directions)
    on_mesh = surface.radius(directions)
    for name, count, radius in zip(names, crossings, on_mesh, strict=True):
        if count != 1 or not np.isfinite(radius):
            raise InputError(
                f"{keys.field}: landmark {name}: the ray from the isocenter through it meets "
                f"the outer surface {count} times; it must meet it once"
            )
    shifts = on_mesh - radii
    far = int(np.argmax(np.abs(shifts)))
    if abs(shifts[far]) > keys.max_landmark_shift:
        where = f" of {origin}" if origin else ""
        side = "outside" if shifts[far] < 0.0 else "inside"
        raise InputError(
            f"{keys.shift_field} = {keys.max_landmark_shift / MM:g}: landmark {names[far]}"
            f"{where} lies {abs(shifts[far]) / MM:.1f} mm {side} the outer surface along its "
            f"direction from the isocenter; expected at most {keys.max_landmark_shift / MM:g} "
            "mm (a point of this skull, in its frame and units?)"
        )
    digest = hashlib.sha256()
    for mesh in (keys.outer, keys.inner):
        if mesh is not None:
            digest.update(np.ascontiguousarray(mesh.vertices).tobytes())
            digest.update(np.ascontiguousarray(mesh.faces).tobytes())
    digest.update(np.float64(keys.depth_margin).tobytes())
    skull = Skull(
        surface=surface,
        outer_mesh=keys.outer,
        inner_mesh=keys.inner,
        landmark_shifts_mm=shifts / MM,
        fingerprint=digest.hexdigest(),
        depth_margin=keys.depth_margin,
        **fit,
    )
    return skull, on_mesh[:, None] * directions
