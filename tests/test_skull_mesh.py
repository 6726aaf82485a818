"""Skull meshes from imaging (reading, frames, repair) and their ray casts from the isocenter,
against analytic spheres, ellipsoids, planes and solids of revolution built in the test."""

import struct
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from spm_opt.base.errors import InputError
from spm_opt.skull import mesh as mesh_module
from spm_opt.skull.mesh import load_mesh, to_robot
from spm_opt.skull.raycast import MeshSurface

FIELD = "skull.outer_mesh"
AXES = np.array([0.09, 0.075, 0.065])
"""Semi-axes of the test ellipsoid, m (a skull's size)."""
INNER_AXES = AXES - 0.006
"""Semi-axes of the ellipsoid inside it: 6 mm of bone along each axis."""

directions = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


def unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, float) / np.linalg.norm(v, axis=-1, keepdims=True)


def ellipsoid_radius(p: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Distance from the centre to the ellipsoid with semi-axes ``axes`` along unit p."""
    return 1.0 / np.sqrt(np.sum((p / axes) ** 2, axis=-1))


@cache
def ellipsoid(axes: tuple[float, float, float], subdivisions: int = 5) -> trimesh.Trimesh:
    """An icosphere stretched onto the ellipsoid: every vertex lies on it."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    return trimesh.Trimesh(sphere.vertices * np.array(axes), sphere.faces)


def sagitta(mesh: trimesh.Trimesh, axes: np.ndarray) -> float:
    """How far inside the ellipsoid the facets reach along a ray, m: the largest gap between
    a triangle's centroid and the surface above it, doubled for safety."""
    centres = mesh.triangles_center
    radii = np.linalg.norm(centres, axis=1)
    return 2.0 * float(np.max(ellipsoid_radius(centres / radii[:, None], axes) - radii))


def tangent_basis(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 0.0, 1.0]) if abs(p[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = unit(np.cross(p, helper))
    return e1, np.cross(p, e1)


def sphere_derivative(f, p: np.ndarray, e: np.ndarray, h: float) -> float:
    """Central difference of f on the unit sphere at p along the tangent e, per rad."""
    return float((f(unit(p + h * e)[None]) - f(unit(p - h * e)[None]))[0] / (2.0 * h))


def write_stl(path: Path, mesh: trimesh.Trimesh, header: bytes = b"") -> Path:
    """A binary STL with the given 80-byte header text."""
    path.write_bytes(header.ljust(80, b" ") + mesh.export(file_type="stl")[80:])
    return path


def one_line(error: pytest.ExceptionInfo, *parts: str) -> str:
    message = str(error.value)
    assert "\n" not in message, message
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"
    return message


# --- radius, gradient, thickness, incidence -------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(st.lists(directions, min_size=1, max_size=20))
def test_the_radius_lies_on_the_ellipsoid_within_the_facets_sagitta(vectors):
    mesh = ellipsoid(tuple(AXES))
    p = unit(np.array(vectors))
    radius = MeshSurface(mesh).radius(p)
    expected = ellipsoid_radius(p, AXES)
    # the facets are chords inside the surface; a ray that Embree (single precision) sends
    # to the facet beside the one it crosses meets that facet's plane just past their edge:
    # (0, 1e-9, -0.5) comes out 1.9e-12 m outside at the pole, so allow a nanometre
    assert np.all(radius <= expected + 1e-9)
    assert np.all(radius >= expected - sagitta(mesh, AXES))


def test_the_radius_on_a_sphere_is_exact_where_the_rays_pass_through_vertices():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.08)
    p = unit(mesh.vertices[::7] + 1e-12)
    np.testing.assert_allclose(MeshSurface(mesh).radius(p), 0.08, rtol=1e-12)


@settings(max_examples=40, deadline=None)
@given(directions)
def test_the_gradient_matches_the_analytic_ellipsoid_within_the_facets(vector):
    mesh = ellipsoid(tuple(AXES))
    surface = MeshSurface(mesh)
    p = unit(np.array(vector))
    _, gradient = surface.radius_gradient(p[None])
    assert abs(gradient[0] @ p) < 1e-12  # tangent to the sphere
    # a facet's normal is off the surface's by about the largest angle between neighbouring
    # facets, and the gradient turns by ρ per radian of it (with a margin for n · p < 1)
    tolerance = 1.5 * AXES.max() * float(mesh.face_adjacency_angles.max())
    for e in tangent_basis(p):
        analytic = sphere_derivative(lambda q: ellipsoid_radius(q, AXES), p, e, 1e-6)
        assert abs(gradient[0] @ e - analytic) < tolerance


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_the_gradient_on_a_flat_triangle_is_the_derivative_of_the_radius(u, v):
    corners = np.array([[0.11, -0.05, 0.02], [-0.04, 0.09, 0.07], [-0.05, -0.06, 0.11]])
    w = 0.1 / 3 + 0.9 * np.array([u, (1 - u) * v, (1 - u) * (1 - v)])  # off the edges
    p = unit(w @ corners)
    surface = MeshSurface(trimesh.Trimesh(corners, [[0, 1, 2]], process=False))
    radius, gradient = surface.radius_gradient(p[None])
    assert radius[0] == pytest.approx(
        (corners[0] @ np.cross(corners[1] - corners[0], corners[2] - corners[0]))
        / (p @ np.cross(corners[1] - corners[0], corners[2] - corners[0])),
        rel=1e-12,
    )
    for e in tangent_basis(p):
        difference = sphere_derivative(surface.radius, p, e, 1e-5)
        assert gradient[0] @ e == pytest.approx(difference, rel=1e-7, abs=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.lists(directions, min_size=1, max_size=20))
def test_the_thickness_between_two_concentric_ellipsoids(vectors):
    outer, inner = ellipsoid(tuple(AXES)), ellipsoid(tuple(INNER_AXES))
    p = unit(np.array(vectors))
    surface = MeshSurface(outer, inner)
    expected = ellipsoid_radius(p, AXES) - ellipsoid_radius(p, INNER_AXES)
    tolerance = sagitta(outer, AXES) + sagitta(inner, INNER_AXES)
    np.testing.assert_allclose(surface.thickness(p), expected, atol=tolerance)
    np.testing.assert_allclose(
        surface.inner_radius(p), ellipsoid_radius(p, INNER_AXES), atol=tolerance
    )
    assert np.all(np.isnan(MeshSurface(outer).thickness(p)))


def test_the_tool_meets_a_sphere_square_on():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.08)
    surface = MeshSurface(mesh)
    # along each facet's normal the ray meets that facet square on (at its circumcentre)
    np.testing.assert_allclose(surface.incidence(mesh.face_normals[::5]), 0.0, atol=1e-12)
    hits = surface.hits(mesh.face_normals[::5])
    assert np.all(hits.triangle == np.arange(len(mesh.faces))[::5])
    rng = np.random.default_rng(1)
    p = unit(rng.normal(size=(500, 3)))
    corners = unit(mesh.triangles.reshape(-1, 3)).reshape(-1, 3, 3)
    facet = float(np.arccos(np.min(np.einsum("fi,fki->fk", mesh.face_normals, corners))))
    assert np.all(surface.incidence(p) <= facet + 1e-12)


@pytest.mark.parametrize(
    "faces", [[[0, 1, 2], [0, 2, 3]], [[0, 2, 1], [0, 3, 2]]], ids=["outward", "inward"]
)
@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(-0.3, 0.3), st.floats(-0.3, 0.3))
def test_the_incidence_on_a_tilted_plane_is_the_analytic_angle(faces, tilt, x, y):
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    e1, e2 = np.cross([0.0, 1.0, 0.0], normal), np.array([0.0, 1.0, 0.0])
    centre = 0.07 * normal
    corners = centre + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) @ np.array([e1, e2])
    patch = trimesh.Trimesh(corners, faces, process=False)
    p = unit(np.array([x, y, 1.0]))
    hits = MeshSurface(patch).hits(p[None])
    assert MeshSurface(patch).incidence(p[None])[0] == pytest.approx(
        np.arctan2(np.linalg.norm(np.cross(normal, p)), normal @ p), abs=1e-12
    )
    np.testing.assert_allclose(hits.normal[0], normal, atol=1e-12)
    assert hits.radius[0] == pytest.approx(0.07 / (normal @ p), rel=1e-12)


# --- crossings and the isocenter ---------------------------------------------------------------


@cache
def mushroom() -> trimesh.Trimesh:
    """A stem (radius 25 mm, z from -50 to 50 mm) under a cap (radius 75 mm, z from 50 to
    75 mm), turned about z: a ray from the origin rising at slope 1.1 to 1.4 leaves the
    stem, enters the cap from below and leaves it through its flat top."""
    profile = np.array([(0, -1), (0.5, -1), (0.5, 1), (1.5, 1), (1.5, 1.5), (0, 1.5)]) * 0.05
    return trimesh.creation.revolve(profile, sections=64)


@settings(max_examples=40, deadline=None)
@given(st.floats(1.1, 1.4), st.floats(0.0, 2 * np.pi))
def test_a_ray_under_an_overhang_crosses_three_times_and_leaves_through_the_top(slope, azimuth):
    p = unit(np.array([np.cos(azimuth), np.sin(azimuth), slope]))
    surface = MeshSurface(mushroom())
    assert surface.crossings(p[None])[0] == 3
    assert surface.radius(p[None])[0] == pytest.approx(0.075 / p[2], rel=1e-12)


def test_a_torus_about_the_origin_is_crossed_twice_and_does_not_contain_it():
    torus = trimesh.creation.torus(0.06, 0.02)
    surface = MeshSurface(torus)
    p = unit(np.array([[1.0, 0.0, 0.0], [0.3, 0.7, 0.0], [0.0, 0.0, 1.0]]))
    np.testing.assert_array_equal(surface.crossings(p), [2, 2, 0])
    assert np.isnan(surface.radius(p)[2]) and surface.hits(p).triangle[2] == -1
    assert not surface.contains_isocenter()


def test_a_sphere_is_crossed_once_from_its_centre_even_through_edges_and_vertices():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.08)
    rng = np.random.default_rng(2)
    edges = unit(sphere.vertices[sphere.edges_unique].mean(axis=1))
    p = np.vstack([unit(rng.normal(size=(300, 3))), unit(sphere.vertices), edges])
    for engine in (sphere, trimesh.Trimesh(sphere.vertices, sphere.faces, use_embree=False)):
        assert np.all(MeshSurface(engine).crossings(p) == 1)


def test_the_rtree_engine_answers_as_embree_does():
    mesh = mushroom()
    rtree = trimesh.Trimesh(mesh.vertices, mesh.faces, use_embree=False)
    assert isinstance(rtree.ray, trimesh.ray.ray_triangle.RayMeshIntersector)
    p = unit(np.random.default_rng(3).normal(size=(200, 3)))
    fast, slow = MeshSurface(mesh), MeshSurface(rtree)
    np.testing.assert_array_equal(fast.crossings(p), slow.crossings(p))
    np.testing.assert_allclose(fast.radius(p), slow.radius(p), rtol=1e-12)
    for surface in (fast, slow):  # no directions, no answers
        assert surface.radius_gradient(np.zeros((0, 3)))[1].shape == (0, 3)


@pytest.mark.parametrize("hole", [False, True], ids=["watertight", "with a hole"])
def test_the_isocenter_is_inside_a_sphere_about_it_and_outside_one_beyond_it(hole):
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.08)
    keep = np.ones(len(sphere.faces), dtype=bool)
    if hole:
        keep[np.argsort(sphere.triangles_center[:, 2])[-30:]] = False  # open at the top
    for shift, inside in ((0.0, True), (0.05, True), (0.09, False), (0.5, False)):
        moved = trimesh.Trimesh(sphere.vertices + [shift, 0.0, 0.0], sphere.faces[keep])
        assert moved.is_watertight != hole
        assert MeshSurface(moved).contains_isocenter() is inside


# --- reading files -----------------------------------------------------------------------------


def skull_like() -> trimesh.Trimesh:
    """An off-centre ellipsoid, mm, in RAS: no symmetry that would hide a wrong frame."""
    mesh = ellipsoid(tuple(AXES * 1e3), subdivisions=3).copy()
    mesh.apply_translation([12.0, -30.0, 45.0])
    return mesh


def test_an_lps_mesh_and_its_ras_copy_land_on_the_same_robot_mesh(tmp_path):
    ras = skull_like()
    lps = trimesh.Trimesh(ras.vertices * [-1.0, -1.0, 1.0], ras.faces)
    angle = 0.3
    matrix = np.array(
        [
            [np.cos(angle), -np.sin(angle), 0.0, 5.0],
            [np.sin(angle), np.cos(angle), 0.0, -20.0],
            [0.0, 0.0, 1.0, -45.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    robot = {
        frame: to_robot(
            load_mesh(write_stl(tmp_path / f"{frame}.stl", m), frame, FIELD), frame, matrix
        )
        for frame, m in (("RAS", ras), ("LPS", lps))
    }
    expected = trimesh.transform_points(np.float32(ras.vertices), matrix) * 1e-3
    for moved in robot.values():
        assert len(moved.faces) == len(ras.faces) and moved.volume > 0
        distance, _ = cKDTree(expected).query(moved.vertices)
        assert distance.max() < 1e-12
    np.testing.assert_allclose(robot["RAS"].volume, robot["LPS"].volume, rtol=1e-12)


@pytest.mark.parametrize("kind", ["binary stl", "ascii stl", "obj", "ply", "off"])
def test_a_header_stating_another_frame_is_refused_and_the_same_frame_accepted(tmp_path, kind):
    mesh = skull_like()

    def written(space: str) -> Path:
        if kind == "binary stl":
            return write_stl(tmp_path / f"{space}.stl", mesh, f"SPACE={space}".encode())
        if kind == "ascii stl":
            text = mesh.export(file_type="stl_ascii").replace("solid", f"solid SPACE={space}", 1)
            suffix = "stl"
        elif kind == "ply":
            text = mesh.export(file_type="ply", encoding="ascii").decode()
            text = text.replace("format ascii 1.0\n", f"format ascii 1.0\ncomment SPACE={space}\n")
            suffix = "ply"
        else:
            text = f"# SPACE={space}\n" + mesh.export(file_type=kind)
            suffix = kind
            if kind == "off":  # OFF must start with its keyword
                text = "OFF\n" + text.replace("OFF\n", "", 1)
        path = tmp_path / f"{space}.{suffix}"
        path.write_text(text)
        return path

    with pytest.raises(InputError) as error:
        load_mesh(written("LPS"), "RAS", FIELD)
    message = one_line(error, "SPACE=LPS", "frame = 'RAS'")
    assert message.startswith(f"{FIELD} = '{tmp_path / 'LPS'}")
    loaded = load_mesh(written("RAS"), "RAS", FIELD)
    assert len(loaded.faces) == len(mesh.faces) and loaded.is_watertight


# --- repair and refusals -----------------------------------------------------------------------


def test_flipped_normals_are_turned_outward(tmp_path):
    mesh = skull_like()
    mesh.invert()
    assert mesh.volume < 0
    loaded = load_mesh(write_stl(tmp_path / "inside_out.stl", mesh), "RAS", FIELD)
    assert loaded.is_watertight and loaded.volume > 0


def test_a_small_hole_is_filled_and_a_large_one_kept_with_normals_outward(tmp_path):
    mesh = skull_like()
    small = trimesh.Trimesh(mesh.vertices, mesh.faces[1:])
    loaded = load_mesh(write_stl(tmp_path / "small.stl", small), "RAS", FIELD)
    assert loaded.is_watertight and len(loaded.faces) == len(mesh.faces)
    top = np.argsort(mesh.triangles_center[:, 2])[-20:]  # a foramen of 20 triangles
    large = trimesh.Trimesh(mesh.vertices, np.delete(mesh.faces, top, axis=0))
    large.invert()
    loaded = load_mesh(write_stl(tmp_path / "large.stl", large), "RAS", FIELD)
    assert not loaded.is_watertight and len(loaded.faces) == len(mesh.faces) - 20
    centres = loaded.triangles_center - loaded.vertices.mean(axis=0)
    assert np.mean(np.einsum("ni,ni->n", loaded.face_normals, centres) > 0) > 0.99


def test_duplicate_and_degenerate_triangles_are_removed(tmp_path):
    mesh = skull_like()
    faces = np.vstack([mesh.faces, mesh.faces[:5], [[0, 0, 1], [2, 2, 2]]])
    loaded = load_mesh(
        write_stl(tmp_path / "messy.stl", trimesh.Trimesh(mesh.vertices, faces, process=False)),
        "RAS",
        FIELD,
    )
    assert len(loaded.faces) == len(mesh.faces) and loaded.is_watertight


def fin() -> trimesh.Trimesh:
    """Three triangles on one edge."""
    vertices = [[0, 0, 0], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0]]
    return trimesh.Trimesh(vertices, [[0, 1, 2], [1, 0, 3], [0, 1, 4]], process=False)


def two_cubes() -> trimesh.Trimesh:
    """Two closed cubes that share one edge."""
    first = trimesh.creation.box([10.0, 10.0, 10.0])
    second = first.copy()
    second.apply_translation([10.0, 10.0, 0.0])
    return trimesh.util.concatenate([first, second])


@pytest.mark.parametrize("make", [fin, two_cubes], ids=["three triangles", "two cubes"])
def test_a_non_manifold_mesh_is_refused(tmp_path, make):
    path = write_stl(tmp_path / "bad.stl", make())
    with pytest.raises(InputError) as error:
        load_mesh(path, "RAS", FIELD)
    assert one_line(error, "1 non-manifold edges").startswith(f"{FIELD} = '{path}': ")


def test_bad_files_are_refused_in_one_line_naming_the_field(tmp_path, monkeypatch):
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(bytes(range(256)) * 7)
    unknown = tmp_path / "skull.xyz"
    unknown.write_text("not a mesh\n")
    flat = write_stl(
        tmp_path / "flat.stl", trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]])
    )
    nan = tmp_path / "nan.stl"  # one facet: normal, three corners, attribute
    nan.write_bytes(
        b" " * 80 + struct.pack("<I12fH", 1, 0, 0, 1, 0, 0, 0, 1, 0, 0, np.nan, 1, 0, 0)
    )
    huge = tmp_path / "huge.stl"
    with huge.open("wb") as stream:
        stream.truncate(501 * 2**20)  # sparse: nothing written
    cases = [
        (tmp_path / "missing.stl", "no such file"),
        (empty, "no triangles"),
        (garbage, "no triangles read"),
        (unknown, "not a mesh trimesh can read"),
        (huge, "501 MB"),
        (flat, "every triangle is degenerate"),
        (nan, "not finite"),
    ]
    for path, reason in cases:
        with pytest.raises(InputError) as error:
            load_mesh(path, "LPS", FIELD)
        assert one_line(error, reason).startswith(f"{FIELD} = '{path}': ")
    monkeypatch.setattr(mesh_module, "MAX_FACES", 100)
    with pytest.raises(InputError) as error:
        load_mesh(write_stl(tmp_path / "many.stl", skull_like()), "RAS", FIELD)
    one_line(error, "1,280 triangles", "at most 100")
