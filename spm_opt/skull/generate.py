"""Made-up skulls of plausible shape and size, for tests and examples (the repository ships
no patient's data).

The cranium is a closed ovoid, star-shaped about its centre: along each unit direction u
from the centre (in RAS: +x right, +y anterior, +z superior), its outer surface lies at the
radius of an ellipsoid whose semi-axes span the paper's Table I (length 190-220 mm,
breadth 140-156 mm, 75-90 mm above the ear plane), narrower in front, flatter below the ear
plane (the skull base), with a few smooth bumps of 1-3 mm; the inner surface lies the
bone's thickness (4-9 mm: thin at the temples, thick in front and behind) nearer the
centre. The meshes sample these radii at an icosphere's vertices, so a seed gives one
smooth skull at any resolution.

    python -m spm_opt.skull.generate --seed 0 --out DIR [--frame RAS|LPS] [--subdivisions 5]

writes a skull and a flap drawn on it, as 3D Slicer would (:func:`write_example`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation
from trimesh.ray.ray_triangle import RayMeshIntersector

from spm_opt.base.errors import InputError
from spm_opt.base.files import write_atomically
from spm_opt.base.input_limits import excerpt
from spm_opt.skull.frames import FRAMES, check_frame, to_ras
from spm_opt.skull.markups import markups_text

SEMI_AXES_MM = {"x": (70.0, 78.0), "y": (95.0, 110.0), "z": (75.0, 90.0)}
"""Ranges the outer semi-axes are drawn from, mm: half the breadth (x), half the length
(y) and the height above the ear plane (z)."""
THICKNESS_MM = (4.0, 9.0)
"""The bone's least and greatest thickness, mm, along the rays from the centre."""
SUBDIVISIONS = range(1, 8)
"""The icosphere's subdivisions allowed: 5 gives 20,480 triangles a surface, 6 81,920,
7 327,680."""
STANDOFF_MM = 75.0
"""How far from the isocenter :func:`write_example` puts the flap's centre, mm."""
FLAP_LABELS = ("F-1", "F-2", "F-3", "F-4", "F-5")
"""The example flap's points, labelled as Slicer labels a curve's points."""


@dataclass(frozen=True)
class SkullParameters:
    """The analytic skull a seed draws: its radii along every direction from its centre.

    Attributes
    ----------
    seed : int
    centre_ras_mm : ndarray (3,)
        The centre (on the ear plane, between the ears) in the image's RAS frame, mm.
    semi_axes_mm : ndarray (3,)
        The outer surface's semi-axes, mm: x (half the breadth), y (half the length), z
        (the height above the ear plane), before the bumps.
    base_depth_mm : float
        The outer surface's depth below the ear plane, mm (the z semi-axis below it).
    frontal_taper : float
        How much narrower the front is: the x semi-axis shrinks by this fraction times
        u_y² for the directions u pointing forward (u_y > 0).
    bumps : ndarray (k, 5)
        The outer surface's Gaussian bumps: direction (3), amplitude (mm, signed) and
        width (standard deviation along the surface, mm).
    thickness_mm : ndarray (3,)
        The bone's thickness t(u) = t0 + t_ap u_y² - t_lat u_x² + noise, clipped to
        :data:`THICKNESS_MM`: (t0, t_ap, t_lat), mm.
    thickness_bumps : ndarray (m, 5)
        The thickness's smooth noise, as :attr:`bumps`.
    """

    seed: int
    centre_ras_mm: np.ndarray
    semi_axes_mm: np.ndarray
    base_depth_mm: float
    frontal_taper: float
    bumps: np.ndarray
    thickness_mm: np.ndarray
    thickness_bumps: np.ndarray

    def outer_radius(self, directions: np.ndarray) -> np.ndarray:
        """The outer surface's distance from the centre (n,), mm, along unit directions
        (n, 3) in RAS."""
        u = np.asarray(directions, dtype=float)
        return self._ellipsoid(u) + self._bump_sum(u, self.bumps)

    def thickness(self, directions: np.ndarray) -> np.ndarray:
        """The bone's thickness along the rays from the centre (n,), mm, within
        :data:`THICKNESS_MM`."""
        u = np.asarray(directions, dtype=float)
        t0, t_ap, t_lat = self.thickness_mm
        smooth = t0 + t_ap * u[:, 1] ** 2 - t_lat * u[:, 0] ** 2
        return np.clip(smooth + self._bump_sum(u, self.thickness_bumps), *THICKNESS_MM)

    def inner_radius(self, directions: np.ndarray) -> np.ndarray:
        """The inner surface's distance from the centre (n,), mm, along unit directions
        (n, 3)."""
        return self.outer_radius(directions) - self.thickness(directions)

    def _ellipsoid(self, u: np.ndarray) -> np.ndarray:
        """The radius (n,), mm, of the ovoid without bumps along unit directions (n, 3)."""
        a_x, a_y, a_z = self.semi_axes_mm
        a_x = a_x * (1.0 - self.frontal_taper * np.maximum(u[:, 1], 0.0) ** 2)
        a_z = np.where(u[:, 2] >= 0.0, a_z, self.base_depth_mm)
        return 1.0 / np.sqrt((u[:, 0] / a_x) ** 2 + (u[:, 1] / a_y) ** 2 + (u[:, 2] / a_z) ** 2)

    def _bump_sum(self, u: np.ndarray, bumps: np.ndarray) -> np.ndarray:
        """The sum (n,), mm, of Gaussian bumps (k, 5) along unit directions u (n, 3); a
        bump's width in mm becomes an angle at the ovoid's radius in its direction."""
        centres, amplitudes, widths = bumps[:, :3], bumps[:, 3], bumps[:, 4]
        angular_width = widths / self._ellipsoid(centres)
        chord_squared = np.maximum(2.0 - 2.0 * u @ centres.T, 0.0)
        return np.exp(-chord_squared / (2.0 * angular_width**2)) @ amplitudes


@dataclass(frozen=True)
class GeneratedSkull:
    """A generated skull's meshes in the image's RAS frame, mm, and what made them.

    Attributes
    ----------
    outer, inner : trimesh.Trimesh
        The bone's outer and inner surfaces, watertight, normals outward; vertex i of each
        lies along :attr:`directions` [i] from the centre.
    parameters : SkullParameters
    directions : ndarray (n, 3)
        The icosphere's unit vertices.
    """

    outer: trimesh.Trimesh
    inner: trimesh.Trimesh
    parameters: SkullParameters
    directions: np.ndarray


def draw_parameters(
    seed: int = 0, *, length_mm: float | None = None, breadth_mm: float | None = None
) -> SkullParameters:
    """The analytic skull of ``seed``; its length (front to back) and breadth (side to
    side), mm, are drawn from :data:`SEMI_AXES_MM` unless given."""
    rng = np.random.default_rng(seed)
    semi_axes = np.array([rng.uniform(*SEMI_AXES_MM[axis]) for axis in "xyz"])
    for index, (name, value, allowed) in enumerate(
        (("breadth_mm", breadth_mm, (100.0, 200.0)), ("length_mm", length_mm, (140.0, 260.0)))
    ):
        if value is not None:
            if not allowed[0] <= value <= allowed[1]:
                raise InputError(
                    f"{name} = {excerpt(value)}: expected a skull's {name[:-3]} from "
                    f"{allowed[0]:g} to {allowed[1]:g} mm"
                )
            semi_axes[index] = value / 2.0
    return SkullParameters(
        seed=seed,
        centre_ras_mm=np.array(
            [rng.uniform(-5.0, 5.0), rng.uniform(-30.0, -10.0), rng.uniform(30.0, 50.0)]
        ),
        semi_axes_mm=semi_axes,
        base_depth_mm=rng.uniform(40.0, 50.0),
        frontal_taper=rng.uniform(0.08, 0.15),
        bumps=_draw_bumps(rng, 6, (1.0, 3.0), (20.0, 40.0)),
        thickness_mm=np.array(
            [rng.uniform(6.0, 7.0), rng.uniform(1.5, 2.5), rng.uniform(2.0, 3.0)]
        ),
        thickness_bumps=_draw_bumps(rng, 4, (0.3, 1.0), (30.0, 50.0)),
    )


def _draw_bumps(
    rng: np.random.Generator,
    count: int,
    amplitudes_mm: tuple[float, float],
    widths_mm: tuple[float, float],
) -> np.ndarray:
    """``count`` bumps (count, 5): random directions, amplitudes of either sign, widths."""
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    signs = rng.choice([-1.0, 1.0], size=count)
    amplitudes = signs * rng.uniform(*amplitudes_mm, size=count)
    widths = rng.uniform(*widths_mm, size=count)
    return np.column_stack([directions, amplitudes, widths])


def generate_skull(
    seed: int = 0,
    subdivisions: int = 5,
    *,
    length_mm: float | None = None,
    breadth_mm: float | None = None,
) -> GeneratedSkull:
    """The skull of ``seed`` (:func:`draw_parameters`) sampled at the vertices of an
    icosphere subdivided ``subdivisions`` times (one of :data:`SUBDIVISIONS`), in the
    image's RAS frame, mm."""
    if subdivisions not in SUBDIVISIONS:
        raise InputError(
            f"subdivisions = {excerpt(subdivisions)}: expected {SUBDIVISIONS[0]} to "
            f"{SUBDIVISIONS[-1]} (5: 20,480 triangles a surface; each more: 4 times as many)"
        )
    parameters = draw_parameters(seed, length_mm=length_mm, breadth_mm=breadth_mm)
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    directions = np.asarray(sphere.vertices)
    centre = parameters.centre_ras_mm

    def surface(radii: np.ndarray) -> trimesh.Trimesh:
        vertices = centre + radii[:, None] * directions
        return trimesh.Trimesh(vertices, sphere.faces.copy(), process=False)

    return GeneratedSkull(
        outer=surface(parameters.outer_radius(directions)),
        inner=surface(parameters.inner_radius(directions)),
        parameters=parameters,
        directions=directions,
    )


def write_example(
    out_dir: Path, seed: int, frame: str = "RAS", subdivisions: int = 5
) -> dict[str, object]:
    """Write a generated skull and a flap on it as 3D Slicer would, and return where they
    are and the image-to-robot transform that brings the flap over the isocenter.

    Writes ``skull_outer.stl`` and ``skull_inner.stl`` (binary, in ``frame``, the header
    starting ``SPACE=RAS`` or ``SPACE=LPS``) and ``flap.mrk.json`` (a ClosedCurve of 5
    points on the outer mesh, in LPS): a flap 30-45 mm across on the top of the head,
    forward and to one side. The transform puts the flap's centre on the robot's +z axis,
    :data:`STANDOFF_MM` from the isocenter on the line from the skull's centre through it,
    with the patient's anterior towards the robot's +x.

    Returns
    -------
    dict
        ``outer``, ``inner``, ``markups`` (paths), ``frame``, ``seed``, ``subdivisions``,
        ``image_to_robot_mm`` (ndarray (4, 4): image RAS mm to robot mm),
        ``flap_centre_ras_mm`` (ndarray (3,)) and ``parameters`` (SkullParameters).
    """
    frame = check_frame(frame, "frame")
    skull = generate_skull(seed, subdivisions)
    centre_point, points = _flap(skull)
    matrix = _image_to_robot(skull.parameters.centre_ras_mm, centre_point)
    out_dir = Path(out_dir)
    paths = {
        "outer": out_dir / "skull_outer.stl",
        "inner": out_dir / "skull_inner.stl",
        "markups": out_dir / "flap.mrk.json",
    }
    write_atomically(
        {
            paths["outer"]: _stl_bytes(skull.outer, frame),
            paths["inner"]: _stl_bytes(skull.inner, frame),
            paths["markups"]: markups_text(FLAP_LABELS, points, frame="LPS", closed=True),
        }
    )
    return {
        **paths,
        "frame": frame,
        "seed": seed,
        "subdivisions": subdivisions,
        "image_to_robot_mm": matrix,
        "flap_centre_ras_mm": centre_point,
        "parameters": skull.parameters,
    }


def _flap(skull: GeneratedSkull) -> tuple[np.ndarray, np.ndarray]:
    """A flap's centre (3,) and its 5 points (5, 3) on the outer mesh, RAS mm: an
    irregular pentagon 30-45 mm across, 20-35° from the vertex, forward and to one side."""
    rng = np.random.default_rng([skull.parameters.seed, 1])
    polar = np.radians(rng.uniform(20.0, 35.0))
    azimuth = np.radians(rng.uniform(20.0, 60.0))  # from anterior towards the side
    side = rng.choice([-1.0, 1.0])
    direction = np.array(
        [
            side * np.sin(polar) * np.sin(azimuth),
            np.sin(polar) * np.cos(azimuth),
            np.cos(polar),
        ]
    )
    circumradius = rng.uniform(33.0, 48.0) / 2.0  # a regular pentagon is 0.95 of 2x across
    angles = 2.0 * np.pi * np.arange(5) / 5 + rng.uniform(-0.1, 0.1, size=5)
    radii = circumradius * rng.uniform(0.95, 1.0, size=5)
    centre = skull.parameters.centre_ras_mm
    centre_point = _on_mesh(skull.outer, centre, direction[None, :])[0]
    first, second = _tangents(direction)
    around = centre_point + radii[:, None] * (
        np.cos(angles)[:, None] * first + np.sin(angles)[:, None] * second
    )
    return centre_point, _on_mesh(skull.outer, centre, around - centre)


def _tangents(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) perpendicular to the unit ``direction`` and to each other."""
    first = np.cross([0.0, 0.0, 1.0], direction)
    first /= np.linalg.norm(first)
    return first, np.cross(direction, first)


def _on_mesh(mesh: trimesh.Trimesh, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Where the rays from ``origin`` (3,) along ``directions`` (n, 3) leave the
    star-shaped ``mesh`` (n, 3), mm: the pure-numpy ray caster, the same on every
    machine (Embree's casts are single precision)."""
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hits, rays, _ = RayMeshIntersector(mesh).intersects_location(
        np.repeat(origin[None, :], len(unit), axis=0), unit, multiple_hits=False
    )
    return hits[np.argsort(rays)]


def _image_to_robot(centre: np.ndarray, flap_centre: np.ndarray) -> np.ndarray:
    """The rigid transform (4, 4), image RAS mm to robot mm, taking ``flap_centre`` to
    (0, 0, :data:`STANDOFF_MM`) and the line from the skull's ``centre`` through it to the
    robot's +z axis, the patient's anterior (RAS +y) as near the robot's +x as it goes."""
    axis = (flap_centre - centre) / np.linalg.norm(flap_centre - centre)
    rotation, _ = Rotation.align_vectors(
        [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], [axis, [0.0, 1.0, 0.0]], weights=[np.inf, 1.0]
    )
    isocenter = flap_centre - STANDOFF_MM * axis
    matrix = np.eye(4)
    matrix[:3, :3] = rotation.as_matrix()
    matrix[:3, 3] = -matrix[:3, :3] @ isocenter
    return matrix


def _stl_bytes(mesh: trimesh.Trimesh, frame: str) -> bytes:
    """A binary STL of ``mesh`` (given in RAS) in ``frame``, its 80-byte header starting
    ``SPACE=<frame>`` as 3D Slicer writes and reads it (trimesh writes zeros there)."""
    turned = trimesh.Trimesh(to_ras(mesh.vertices, frame), mesh.faces, process=False)
    data = turned.export(file_type="stl")
    return f"SPACE={frame}".encode("ascii").ljust(80, b" ") + data[80:]


def main(argv: list[str] | None = None) -> None:
    """The command line: write an example skull and flap, and print what was written."""
    parser = argparse.ArgumentParser(
        prog="python -m spm_opt.skull.generate", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True, help="the folder to write to")
    parser.add_argument("--frame", choices=FRAMES, default="RAS", help="the meshes' frame")
    parser.add_argument("--subdivisions", type=int, default=5)
    args = parser.parse_args(argv)
    try:
        example = write_example(args.out, args.seed, args.frame, args.subdivisions)
    except InputError as error:
        parser.error(str(error))
    for key in ("outer", "inner", "markups"):
        print(f"wrote {example[key]}")
    rows = ", ".join(
        "[" + ", ".join(f"{value:.12g}" for value in row) + "]"
        for row in example["image_to_robot_mm"]
    )
    print(f"image_to_robot = [{rows}]  # image RAS mm to robot mm")


if __name__ == "__main__":
    main()
