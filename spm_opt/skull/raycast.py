"""The skull's surfaces as seen from the isocenter: ray casts along the tool's axis.

Rays leave the isocenter (the robot's origin) along unit directions p. The outer surface's
radius ρ(p) is where a ray leaves the outer mesh for the last time (its farthest crossing),
the inner surface's where it leaves the inner mesh. Every crossing is found in one batch by
the mesh's ray engine (Embree where ``embreex`` is installed, in single precision; else
trimesh's rtree engine, in batches that bound its memory); each triangle found is then
intersected with the ray again in double precision, so radii are exact to rounding on the
triangulated surface (a ray that the single-precision engine sends to the facet beside the
one it crosses meets that facet's plane just past their edge: 1.9e-12 m off at a pole of
the test ellipsoid).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.base.errors import require

if TYPE_CHECKING:
    import trimesh

DUPLICATE_HIT = 1e-9
"""Hits along one ray closer than this (m) are one crossing (a ray through an edge or a
vertex meets every triangle that shares it)."""
RTREE_PAIRS = 2_000_000
"""Without Embree, rays are cast in batches of at most this many (ray, triangle) pairs: the
rtree engine tests each ray against every triangle its bounding box meets."""


@dataclass(frozen=True)
class OuterHits:
    """Where rays from the isocenter leave a mesh for the last time.

    Attributes
    ----------
    radius : ndarray (N,), m
        Distance from the isocenter along the ray; NaN where it misses.
    normal : ndarray (N, 3)
        Outward unit normal of the triangle hit (n · p ≥ 0, whatever the mesh's winding);
        NaN where the ray misses.
    triangle : ndarray (N,), int
        Index of the triangle hit in the mesh's faces; -1 where the ray misses.
    """

    radius: np.ndarray
    normal: np.ndarray
    triangle: np.ndarray


class MeshSurface:
    """The skull's outer (and optionally inner) surface in the robot's frame, m, by ray casts
    from the isocenter.

    Parameters
    ----------
    outer : trimesh.Trimesh
        The skull's outer surface, in the robot's frame, m.
    inner : trimesh.Trimesh or None
        Its inner surface, in the robot's frame, m.

    Every method takes unit directions (N, 3) and answers for each.
    """

    def __init__(self, outer: trimesh.Trimesh, inner: trimesh.Trimesh | None = None) -> None:
        self.outer, self.inner = outer, inner
        self._outer = _prepared(outer)
        self._inner = None if inner is None else _prepared(inner)

    def hits(self, directions: np.ndarray) -> OuterHits:
        """Where rays along ``directions`` leave the outer surface (the farthest crossing)."""
        return _last_hits(self._outer, _rows(directions))

    def crossings(self, directions: np.ndarray) -> np.ndarray:
        """How many times (N,) each ray crosses the outer surface (hits within
        :data:`DUPLICATE_HIT` of each other along a ray count once)."""
        p = _rows(directions)
        return np.bincount(_all_hits(self._outer, p)[0], minlength=len(p))

    def radius(self, directions: np.ndarray) -> np.ndarray:
        """Outer radius (N,), m; NaN where a ray misses."""
        return self.hits(directions).radius

    def radius_gradient(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Outer radius (N,), m, and its gradient on the unit sphere (N, 3), m/rad, tangent to
        it: on the hit triangle's plane n · d(ρ p) = 0, so ∇ρ = −ρ (n − (n·p) p) / (n·p)."""
        p = _rows(directions)
        hits = _last_hits(self._outer, p)
        along = np.einsum("ni,ni->n", hits.normal, p)
        tangent = hits.normal - along[:, None] * p
        return hits.radius, -(hits.radius / along)[:, None] * tangent

    def inner_radius(self, directions: np.ndarray) -> np.ndarray:
        """Inner radius (N,), m, the farthest crossing of the inner surface; NaN without an
        inner surface or where a ray misses it."""
        p = _rows(directions)
        if self._inner is None:
            return np.full(len(p), np.nan)
        return _last_hits(self._inner, p).radius

    def thickness(self, directions: np.ndarray) -> np.ndarray:
        """The bone along the tool's axis (N,), m: outer radius − inner radius (NaN where
        either is)."""
        p = _rows(directions)
        return self.radius(p) - self.inner_radius(p)

    def incidence(self, directions: np.ndarray) -> np.ndarray:
        """Angle (N,), rad, between the tool's axis and the outer surface's normal where it
        meets it: 0 when the tool meets the bone square on; NaN where a ray misses."""
        p = _rows(directions)
        normal = self.hits(p).normal  # arctan2 keeps small angles exact, unlike arccos
        sine = np.linalg.norm(np.cross(normal, p), axis=1)
        return np.arctan2(sine, np.einsum("ni,ni->n", normal, p))

    def contains_isocenter(self) -> bool:
        """Whether the isocenter lies inside the outer surface: ``mesh.contains`` for a
        watertight mesh, else an odd number of crossings along most of 14 rays spread over
        the sphere (a hole may spoil one)."""
        if self.outer.is_watertight:
            return bool(self.outer.contains(np.zeros((1, 3)))[0])
        odd = self.crossings(_PROBES) % 2 == 1
        return int(np.count_nonzero(odd)) > len(_PROBES) // 2


def _probes() -> np.ndarray:
    """14 unit directions (the faces and corners of a cube), turned off the coordinate axes
    where a symmetric mesh has its edges and vertices."""
    axes = np.vstack([np.eye(3), -np.eye(3)])
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    rays = np.vstack([axes, corners / np.sqrt(3.0)])
    tilt = np.linalg.qr(np.array([[0.9, 0.3, 0.1], [-0.2, 0.8, 0.4], [0.3, -0.2, 0.9]]))[0]
    return rays @ tilt


_PROBES = _probes()


def _rows(directions: np.ndarray) -> np.ndarray:
    """Directions as a float array (N, 3)."""
    return np.atleast_2d(np.asarray(directions, dtype=float))


@dataclass(frozen=True)
class _Prepared:
    """A mesh's ray engine and its triangles' normals and first corners as plain arrays:
    trimesh hashes a mesh's arrays to check its caches on every access, which cost 0.7 s of
    toppra's 1.7 s over three plans on 327,680 triangles."""

    ray: object
    normals: np.ndarray
    corners: np.ndarray
    step: int


def _prepared(mesh: trimesh.Trimesh) -> _Prepared:
    """The mesh ready for :func:`_all_hits` (its rays batched without Embree)."""
    rtree = require("trimesh", "a skull mesh").ray.ray_triangle.RayMeshIntersector
    engine = mesh.ray
    faces = np.asarray(mesh.faces)
    step = max(1, RTREE_PAIRS // len(faces)) if isinstance(engine, rtree) else 2**62
    return _Prepared(
        engine, np.array(mesh.face_normals), np.array(mesh.vertices)[faces[:, 0]], step
    )


def _all_hits(mesh: _Prepared, p: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every crossing of the rays from the origin along unit directions ``p`` (N, 3) with
    ``mesh``, ordered by ray then distance, hits within :data:`DUPLICATE_HIT` merged: the
    rays' indices, the distances (m, exact on the triangles' planes in double precision) and
    the triangles' indices."""
    triangles, rays = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for start in range(0, len(p), mesh.step):
        chunk = p[start : start + mesh.step]
        found = mesh.ray.intersects_id(np.zeros_like(chunk), chunk, multiple_hits=True)
        triangles.append(found[0])
        rays.append(found[1] + start)
    triangle, ray = np.concatenate(triangles), np.concatenate(rays)
    normals = mesh.normals[triangle]
    corners = mesh.corners[triangle]
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = np.einsum("ni,ni->n", normals, corners) / np.einsum("ni,ni->n", normals, p[ray])
    keep = np.isfinite(distance) & (distance > 0.0)
    order = np.lexsort((distance[keep], ray[keep]))
    ray, distance, triangle = ray[keep][order], distance[keep][order], triangle[keep][order]
    new = np.ones(len(ray), dtype=bool)
    new[1:] = (ray[1:] != ray[:-1]) | (np.diff(distance) > DUPLICATE_HIT)
    return ray[new], distance[new], triangle[new]


def _last_hits(mesh: _Prepared, p: np.ndarray) -> OuterHits:
    """The farthest crossing of each ray from the origin along unit directions ``p``."""
    ray, distance, triangle = _all_hits(mesh, p)
    last = np.ones(len(ray), dtype=bool)
    last[:-1] = ray[1:] != ray[:-1]
    ray, distance, triangle = ray[last], distance[last], triangle[last]
    radius = np.full(len(p), np.nan)
    radius[ray] = distance
    normals = mesh.normals[triangle]
    normal = np.full((len(p), 3), np.nan)
    normal[ray] = normals * np.sign(np.einsum("ni,ni->n", normals, p[ray]))[:, None]
    chosen = np.full(len(p), -1, dtype=np.int64)
    chosen[ray] = triangle
    return OuterHits(radius, normal, chosen)
