"""The skull's inputs: the imaging frames, 3D Slicer's markups files and the image-to-robot
registration (fitted to fiducials, or a matrix checked to be rigid)."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from spm_opt.base.errors import InputError
from spm_opt.model.rigid import apply
from spm_opt.skull.frames import FRAMES, check_frame, frame_matrix, to_ras
from spm_opt.skull.markups import MAX_MARKUPS_BYTES, SCHEMA, read_markups, write_markups
from spm_opt.skull.registration import (
    MAX_FIDUCIAL_CONDITION,
    check_residuals,
    check_transform,
    fiducial_condition,
    fit_rigid,
)

COORDINATES = st.floats(-500.0, 500.0, allow_nan=False)


def _one_line(error: pytest.ExceptionInfo[InputError], *parts: str) -> str:
    """The error's message, checked to be one line containing every part."""
    message = str(error.value)
    assert "\n" not in message, message
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"
    return message


# --- frames -----------------------------------------------------------------------------


@given(arrays(float, (5, 3), elements=COORDINATES), st.sampled_from(FRAMES))
def test_to_ras_negates_x_and_y_of_lps_and_is_its_own_inverse(points, frame):
    ras = to_ras(points, frame)
    signs = [-1.0, -1.0, 1.0] if frame == "LPS" else [1.0, 1.0, 1.0]
    np.testing.assert_array_equal(ras, points * signs)
    np.testing.assert_array_equal(to_ras(ras, frame), points)
    homogeneous = np.column_stack([points, np.ones(len(points))]) @ frame_matrix(frame).T
    np.testing.assert_array_equal(homogeneous[:, :3], ras)


@pytest.mark.parametrize("value", ["ras", "Lps", "XYZ", "", None, 3])
def test_check_frame_takes_upper_case_ras_or_lps_only(value):
    assert [check_frame(frame, "skull.frame") for frame in FRAMES] == list(FRAMES)
    with pytest.raises(InputError) as error:
        check_frame(value, "skull.frame")
    _one_line(error, "skull.frame", repr(value), "'RAS' or 'LPS'", "upper case")


# --- markups ----------------------------------------------------------------------------


def _slicer_point(index: int, label: str, position: list, status: str = "defined") -> dict:
    """A control point as 3D Slicer 5 writes it (LPS orientation)."""
    return {
        "id": str(index + 1),
        "label": label,
        "description": "",
        "associatedNodeID": "vtkMRMLModelNode4",
        "position": position,
        "orientation": [-1.0, -0.0, -0.0, -0.0, -1.0, -0.0, 0.0, 0.0, 1.0],
        "selected": True,
        "locked": False,
        "visibility": True,
        "positionStatus": status,
    }


def _slicer_file(path: Path, points: list[dict], **markup: object) -> Path:
    """A markups file with one markup (a ClosedCurve in LPS mm unless ``markup`` says
    otherwise), with Slicer's display and measurement entries."""
    content = {
        "type": "ClosedCurve",
        "coordinateSystem": "LPS",
        "coordinateUnits": "mm",
        "locked": False,
        "fixedNumberOfControlPoints": False,
        "labelFormat": "%N-%d",
        "lastUsedControlPointNumber": len(points),
        "controlPoints": points,
        "measurements": [
            {"name": "length", "enabled": True, "value": 120.3, "units": "mm", "printFormat": ""}
        ],
        "display": {"visibility": True, "opacity": 1.0, "color": [0.4, 1.0, 1.0]},
    }
    content.update(markup)
    path.write_text(json.dumps({"@schema": SCHEMA, "markups": [content]}, indent=4))
    return path


PENTAGON_LPS = [
    [-31.5, -42.1, 95.2],
    [-48.0, -20.7, 91.3],
    [-40.2, 2.9, 96.8],
    [-15.6, 1.4, 104.0],
    [-9.8, -24.0, 104.9],
]


def test_a_slicer_closed_curve_in_lps_reads_to_ras_without_its_preview_point(tmp_path):
    points = [_slicer_point(i, f"F-{i + 1}", p) for i, p in enumerate(PENTAGON_LPS)]
    points.append(_slicer_point(5, "F-6", [0.0, 0.0, 0.0], status="preview"))
    markups = read_markups(_slicer_file(tmp_path / "flap.mrk.json", points))
    assert markups.labels == ("F-1", "F-2", "F-3", "F-4", "F-5")
    np.testing.assert_array_equal(markups.points_ras_mm, np.array(PENTAGON_LPS) * [-1, -1, 1])
    assert markups.closed and markups.kind == "ClosedCurve"
    assert markups.source == str(tmp_path / "flap.mrk.json")


def test_micrometres_in_ras_and_the_defaults_of_absent_keys(tmp_path):
    um = [_slicer_point(i, "", [1000.0 * v for v in p]) for i, p in enumerate(PENTAGON_LPS)]
    markups = read_markups(
        _slicer_file(tmp_path / "um.mrk.json", um, coordinateSystem="RAS", coordinateUnits="um")
    )
    np.testing.assert_allclose(markups.points_ras_mm, PENTAGON_LPS, rtol=1e-15)
    assert markups.labels == ("P1", "P2", "P3", "P4", "P5")
    bare = [{"position": p} for p in PENTAGON_LPS[:3]]  # no status, label, frame or units
    path = tmp_path / "bare.mrk.json"
    path.write_text(json.dumps({"markups": [{"type": "Fiducial", "controlPoints": bare}]}))
    markups = read_markups(path)
    np.testing.assert_array_equal(markups.points_ras_mm, np.array(PENTAGON_LPS[:3]) * [-1, -1, 1])
    assert not markups.closed and markups.kind == "Fiducial"


@settings(max_examples=40, deadline=None)
@given(
    points=st.integers(2, 12).flatmap(
        lambda n: arrays(float, (n, 3), elements=st.floats(-1e4, 1e4, allow_nan=False))
    ),
    frame=st.sampled_from(FRAMES),
    closed=st.booleans(),
)
def test_write_then_read_gives_the_same_ras_points_in_either_frame(points, frame, closed):
    labels = [f"F-{i + 1}" for i in range(len(points))]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "curve.mrk.json"
        write_markups(path, labels, points, frame=frame, closed=closed)
        data = json.loads(path.read_text())
        markups = read_markups(path)
        assert [p.name for p in Path(folder).iterdir()] == ["curve.mrk.json"]
    assert data["@schema"] == SCHEMA and data["markups"][0]["coordinateSystem"] == frame
    np.testing.assert_array_equal(markups.points_ras_mm, points)
    assert markups.labels == tuple(labels) and markups.closed == closed
    assert markups.kind == ("ClosedCurve" if closed else "Curve")


def _point(position: object, label: str = "F-1", **keys: object) -> dict:
    return {"label": label, "position": position, **keys}


TWO = [_point([1.0, 2.0, 3.0]), _point([4.0, 5.0, 6.0], "F-2")]
BAD_MARKUPS = {
    "not JSON": ('{"markups": [', ("not JSON",)),
    "not an object": ("[1, 2]", ("[1, 2]", "JSON object", "markups list")),
    "no markups list": ('{"markups": {"type": "Curve"}}', ("markups = {", "list of markups")),
    "no markups": ('{"@schema": "x"}', ("markups = None", "list of markups")),
    "empty": ('{"markups": []}', ("0 markups", "expected one")),
    "two markups": (
        {"markups": [{"type": "Curve", "controlPoints": TWO}] * 2},
        ("2 markups", "keep one"),
    ),
    "a plane": (
        {"markups": [{"type": "Plane", "controlPoints": TWO}]},
        ("markups[0].type", "'Plane'", "'Fiducial'", "'Curve'", "'ClosedCurve'"),
    ),
    "unknown type": (
        {"markups": [{"type": "Spline", "controlPoints": TWO}]},
        ("markups[0].type", "'Spline'", "'ClosedCurve'"),
    ),
    "no type": ({"markups": [{"controlPoints": TWO}]}, ("markups[0].type", "None")),
    "frame": (
        {"markups": [{"type": "Curve", "coordinateSystem": "IJK", "controlPoints": TWO}]},
        ("markups[0].coordinateSystem", "'IJK'", "'LPS'", "'RAS'"),
    ),
    "units": (
        {"markups": [{"type": "Curve", "coordinateUnits": "cm", "controlPoints": TWO}]},
        ("markups[0].coordinateUnits", "'cm'", "'mm'", "'um'"),
    ),
    "no placed point": (
        {
            "markups": [
                {
                    "type": "Curve",
                    "controlPoints": [
                        _point([1, 2, 3], positionStatus="preview"),
                        _point([1, 2, 4], "F-2", positionStatus="undefined"),
                    ],
                }
            ]
        },
        ("controlPoints", "no placed point", "at least 2"),
    ),
    "one point": (
        {"markups": [{"type": "Fiducial", "controlPoints": TWO[:1]}]},
        ("controlPoints", "1 placed point", "'F-1'", "at least 2"),
    ),
    "two numbers": (
        {"markups": [{"type": "Curve", "controlPoints": [TWO[0], _point([1, 2], "F-2")]}]},
        ("controlPoints[1] ('F-2').position", "[1, 2]", "3 finite numbers"),
    ),
    "a string": (
        {"markups": [{"type": "Curve", "controlPoints": [_point([1, "a", 2], "X"), TWO[1]]}]},
        ("controlPoints[0] ('X').position", "'a'", "3 finite numbers"),
    ),
    "NaN": (
        '{"markups": [{"type": "Curve", "controlPoints": [{"label": "F-1", '
        '"position": [1, NaN, 2]}, {"label": "F-2", "position": [0, 0, 0]}]}]}',
        ("controlPoints[0] ('F-1').position", "nan", "3 finite numbers"),
    ),
    "a huge integer": (
        {"markups": [{"type": "Curve", "controlPoints": [TWO[0], _point([10**400, 0, 0], "B")]}]},
        ("controlPoints[1] ('B').position", "3 finite numbers"),
    ),
    "a boolean": (
        {"markups": [{"type": "Curve", "controlPoints": [TWO[0], _point([True, 0, 0], "B")]}]},
        ("controlPoints[1] ('B').position", "True", "3 finite numbers"),
    ),
    "labels twice": (
        {"markups": [{"type": "Curve", "controlPoints": [TWO[0], TWO[0]]}]},
        ("controlPoints[1].label", "'F-1'", "unique"),
    ),
    "status": (
        {"markups": [{"type": "Curve", "controlPoints": [_point([1, 2, 3], positionStatus="x")]}]},
        ("controlPoints[0].positionStatus", "'x'", "'defined'"),
    ),
}


@pytest.mark.parametrize("case", BAD_MARKUPS)
def test_a_bad_markups_file_gets_one_line_naming_the_file_and_the_field(tmp_path, case):
    content, parts = BAD_MARKUPS[case]
    path = tmp_path / "flap.mrk.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(InputError) as error:
        read_markups(path)
    assert _one_line(error, *parts).startswith(f"{path}: ")


def test_a_missing_markups_file_or_a_folder_is_named(tmp_path):
    for path, part in ((tmp_path / "none.mrk.json", "no such file"), (tmp_path, "directory")):
        with pytest.raises(InputError) as error:
            read_markups(path)
        assert _one_line(error, part).startswith(f"{path}: ")


def test_a_markups_file_over_10_mb_is_refused_before_it_is_parsed(tmp_path):
    path = tmp_path / "big.mrk.json"
    path.write_bytes(b"[" * (MAX_MARKUPS_BYTES + 1))  # would exhaust the parser's recursion
    with pytest.raises(InputError) as error:
        read_markups(path)
    assert _one_line(error, f"{MAX_MARKUPS_BYTES + 1:,} bytes").startswith(f"{path}: ")
    path.write_bytes(b"[" * 100_000)
    with pytest.raises(InputError) as error:
        read_markups(path)
    _one_line(error, str(path), "not JSON")


# --- registration -----------------------------------------------------------------------


def _rigid(seed: int, translation: np.ndarray) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    matrix[:3, 3] = translation
    return matrix


def _condition(points: np.ndarray) -> float:
    """The fiducials' condition number, from the eigenvalues of their scatter matrix: the
    square root of the largest over the second largest."""
    centred = points - points.mean(axis=0)
    eigenvalues = np.sort(np.linalg.eigvalsh(centred.T @ centred))[::-1]
    return float(np.sqrt(eigenvalues[0] / eigenvalues[1])) if eigenvalues[1] > 0 else np.inf


def _not_collinear(points: np.ndarray) -> bool:
    """Whether the points span a plane well: their condition number at most half the bound,
    and a second singular value above 1 mm."""
    centred = points - points.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)[1] > 1.0
    return spread and _condition(points) <= MAX_FIDUCIAL_CONDITION / 2


FIDUCIALS = st.integers(3, 10).flatmap(
    lambda n: arrays(float, (n, 3), elements=st.floats(-150.0, 150.0, allow_nan=False))
)
TRANSLATIONS = arrays(float, 3, elements=st.floats(-300.0, 300.0, allow_nan=False))


@settings(max_examples=60, deadline=None)
@given(image=FIDUCIALS, seed=st.integers(0, 2**32 - 1), translation=TRANSLATIONS)
def test_fit_rigid_recovers_a_rigid_transform(image, seed, translation):
    assume(_not_collinear(image))
    truth = _rigid(seed, translation)
    fit = fit_rigid(image, apply(truth, image), "fiducials")
    np.testing.assert_allclose(fit.matrix_mm, truth, atol=1e-9)
    assert fit.rms_mm < 1e-9 and fit.residuals_mm.shape == (len(image),)
    assert np.linalg.det(fit.matrix_mm[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_array_equal(check_transform(fit.matrix_mm, "fit"), fit.matrix_mm)


@settings(max_examples=40, deadline=None)
@given(
    image=FIDUCIALS,
    seed=st.integers(0, 2**32 - 1),
    translation=TRANSLATIONS,
    noise_seed=st.integers(0, 2**32 - 1),
)
def test_with_noise_the_rms_is_that_of_the_residuals(image, seed, translation, noise_seed):
    assume(_not_collinear(image))
    noise = np.random.default_rng(noise_seed).normal(scale=0.5, size=image.shape)
    robot = apply(_rigid(seed, translation), image) + noise
    fit = fit_rigid(image, robot, "fiducials")
    moved = image @ fit.matrix_mm[:3, :3].T + fit.matrix_mm[:3, 3]
    residuals = np.sqrt(np.sum((moved - robot) ** 2, axis=1))
    np.testing.assert_allclose(fit.residuals_mm, residuals, atol=1e-12)
    assert fit.rms_mm == pytest.approx(np.sqrt(np.mean(residuals**2)), abs=1e-12)
    # the fit is the least-squares one: the true transform does no better
    truth_rms = np.sqrt(np.mean(np.sum((apply(_rigid(seed, translation), image) - robot) ** 2, 1)))
    assert fit.rms_mm <= truth_rms + 1e-9


def test_a_mirrored_set_is_fitted_by_a_rotation_not_a_mirror():
    image = np.array([[0.0, 0, 0], [50, 0, 0], [0, 40, 0], [0, 0, 30]])
    fit = fit_rigid(image, image * [-1, 1, 1], "fiducials")
    assert np.linalg.det(fit.matrix_mm[:3, :3]) == pytest.approx(1.0)
    assert fit.rms_mm > 1.0


TRIANGLE = np.array([[0.0, 0, 0], [50, 0, 0], [0, 40, 0]])
BAD_FIDUCIALS = {
    "too few": (TRIANGLE[:2], TRIANGLE[:2], ("2 image fiducials", "at least 3")),
    "counts": (TRIANGLE, np.vstack([TRIANGLE, [1, 1, 1]]), ("3 image", "4 robot")),
    "collinear": (
        np.array([[0.0, 0, 0], [10, 10, 10], [20, 20, 20 + 1e-7], [-5, -5, -5]]),
        TRIANGLE[[0, 1, 2, 0]],
        ("4 image fiducials are degenerate: they lie near one line", "undetermined"),
    ),
    "collinear robot": (TRIANGLE, np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), ("robot",)),
    "NaN": (np.array([[0.0, 0, 0], [1, np.nan, 0], [0, 1, 0]]), TRIANGLE, ("nan", "finite")),
    "shape": (np.zeros((3, 2)), TRIANGLE, ("[x, y, z]",)),
    "ragged": ([[0, 0, 0], [1, 0]], TRIANGLE, ("[x, y, z]",)),
}


@pytest.mark.parametrize("case", BAD_FIDUCIALS)
def test_bad_fiducials_get_one_line_naming_the_field(case):
    image, robot, parts = BAD_FIDUCIALS[case]
    with pytest.raises(InputError) as error:
        fit_rigid(image, robot, "skull.registration.image_fiducials_mm")
    assert _one_line(error, *parts).startswith("skull.registration.image_fiducials_mm: ")


WELL_SPREAD = (
    st.integers(3, 8)
    .flatmap(lambda n: arrays(float, (n, 3), elements=st.floats(-120.0, 120.0, allow_nan=False)))
    .filter(_not_collinear)
)


@settings(max_examples=60, deadline=None)
@given(
    image=WELL_SPREAD,
    seed=st.integers(0, 2**32 - 1),
    translation=TRANSLATIONS,
    wrong=st.integers(0, 7),
    error=arrays(float, 3, elements=st.floats(-25.0, 25.0, allow_nan=False)),
)
def test_a_fit_with_a_residual_above_the_bound_names_the_fiducial(
    image, seed, translation, wrong, error
):
    """One fiducial located wrongly by up to 25 mm in each axis: each residual is the one
    trimesh's own rigid fit gives, and the fit is refused exactly when the largest exceeds
    the bound, naming that fiducial (1-based) and every residual."""
    robot = apply(_rigid(seed, translation), image)
    robot[wrong % len(image)] += error
    assume(_not_collinear(robot))  # the error may leave them on a line: another refusal
    fit = fit_rigid(image, robot, "image_fiducials_mm")
    matrix, _, _ = trimesh.registration.procrustes(image, robot, reflection=False, scale=False)
    residuals = np.linalg.norm(image @ matrix[:3, :3].T + matrix[:3, 3] - robot, axis=1)
    np.testing.assert_allclose(fit.residuals_mm, residuals, atol=1e-6)
    bound = 2.0
    assume(abs(residuals.max() - bound) > 1e-6)
    if residuals.max() < bound:
        check_residuals(fit, bound, "max_fiducial_residual_mm")
        return
    with pytest.raises(InputError) as refused:
        check_residuals(fit, bound, "max_fiducial_residual_mm")
    worst = int(np.argmax(fit.residuals_mm))
    each = ", ".join(f"{r:.2f}" for r in fit.residuals_mm)
    assert str(refused.value) == (
        f"max_fiducial_residual_mm = 2: fiducial {worst + 1} of {len(image)} has the largest "
        f"residual, {fit.residuals_mm[worst]:.2f} mm (each: {each} mm; RMS {fit.rms_mm:.2f} "
        "mm); expected at most 2 mm: check where the fiducials were located in both frames "
        "(the fit spreads one's error over others)"
    )


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(3, 8),
    seed=st.integers(0, 2**32 - 1),
    translation=TRANSLATIONS,
    off=st.floats(0.0, 0.001),
    length=st.floats(20.0, 300.0),
)
def test_fiducials_near_one_line_are_named_degenerate(n, seed, translation, off, length):
    """Fiducials along a line 20 to 300 mm long, each at most 0.001 mm off it, in any
    frame: refused at registration as degenerate, by their condition number, in the image
    or in the robot's frame."""
    rng = np.random.default_rng(seed)
    direction = Rotation.random(random_state=seed).apply([1.0, 0.0, 0.0])
    along = np.linspace(-length / 2, length / 2, n)
    line = np.outer(along, direction) + rng.uniform(-1.0, 1.0, (n, 3)) * off / np.sqrt(3)
    line = apply(_rigid(seed, translation), line)
    angles = 2 * np.pi * np.arange(n) / n
    circle = 50.0 * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(n)])
    assert _condition(line) > MAX_FIDUCIAL_CONDITION >= _condition(circle)
    for image, robot, kind in ((line, circle, "image"), (circle, line, "robot")):
        with pytest.raises(InputError) as refused:
            fit_rigid(image, robot, "fiducials")
        _one_line(
            refused,
            f"fiducials: the {n} {kind} fiducials are degenerate: they lie near one line "
            "(condition number ",
            f"at most {MAX_FIDUCIAL_CONDITION:g}), which leaves the rotation about it undetermined",
        )


@settings(max_examples=40, deadline=None)
@given(image=WELL_SPREAD)
def test_the_condition_number_is_that_of_the_scatter_matrix(image):
    assert fiducial_condition(image) == pytest.approx(_condition(image), rel=1e-9)


def _matrix(upper: np.ndarray, last_row=(0.0, 0.0, 0.0, 1.0)) -> list:
    matrix = np.eye(4)
    matrix[:3, :3] = upper
    matrix[:3, 3] = [1.0, 20.0, -6.0]
    matrix[3] = last_row
    return matrix.tolist()


ROTATION = Rotation.from_euler("xyz", [10, -20, 35], degrees=True).as_matrix()
BAD_TRANSFORMS = {
    "mirror": (_matrix(ROTATION @ np.diag([1.0, 1.0, -1.0])), ("determinant -1", "mirror")),
    "scale": (_matrix(1.01 * ROTATION), ("not orthonormal", "scale is not allowed")),
    "shear": (_matrix(ROTATION + 1e-4), ("not orthonormal",)),
    "last row": (_matrix(ROTATION, (0.0, 0.0, 0.1, 1.0)), ("last row", "[0, 0, 0, 1]")),
    "NaN": (_matrix(np.full((3, 3), np.nan)), ("nan", "finite")),
    "3x4": (_matrix(ROTATION)[:3], ("shape (3, 4)", "4 rows of 4")),
    "text": ([["a"] * 4] * 4, ("'a'", "4 rows of 4")),
}


@pytest.mark.parametrize("case", BAD_TRANSFORMS)
def test_check_transform_refuses_what_is_not_rigid(case):
    matrix, parts = BAD_TRANSFORMS[case]
    with pytest.raises(InputError) as error:
        check_transform(matrix, "skull.image_to_robot")
    assert _one_line(error, *parts).startswith("skull.image_to_robot")


def test_check_transform_takes_a_rotation_and_translation():
    matrix = _matrix(ROTATION)
    np.testing.assert_array_equal(check_transform(matrix, "m"), matrix)
    points = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, 9.0]])
    np.testing.assert_allclose(apply(np.array(matrix), points), points @ ROTATION.T + [1, 20, -6])
