"""Motion-capture verification: registration, path deviation, synthetic captures, CSV files."""

import pickle
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from spm_opt.base.errors import InputError
from spm_opt.model.params import load_robot
from spm_opt.verify import motion_capture as mc

ROOT = Path(__file__).resolve().parents[1]
MM = 1e-3
LANDMARKS = mc.reference_landmarks(0.19)


def _circle_path(n: int = 401) -> tuple[np.ndarray, np.ndarray]:
    """A 20 s circle on the platform sphere (r_u = 171.33 mm), 30° from the top."""
    times = np.linspace(0.0, 20.0, n)
    angle = 2 * np.pi * times / 20.0
    s, c = np.sin(np.pi / 6), np.cos(np.pi / 6)
    path = 0.17133 * np.column_stack([s * np.cos(angle), s * np.sin(angle), np.full_like(times, c)])
    return times, path


def _transform(points: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    return points @ rotation.T + translation


# --- reference landmarks ---------------------------------------------------------------


def test_reference_landmarks_are_eight_spread_points_not_coplanar() -> None:
    robot = load_robot(ROOT / "problems" / "robots" / "prototype.toml")
    points = mc.reference_landmarks(robot)
    assert points.shape == (8, 3)
    np.testing.assert_allclose(np.hypot(points[:, 0], points[:, 1]), 0.19)
    singular = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    assert singular[2] > 0.05 * singular[0]  # not coplanar
    assert np.all(points[:, 2] <= 0.0)  # on the base, at or below the isocenter plane
    np.testing.assert_allclose(mc.reference_landmarks(0.19), points)
    with pytest.raises(InputError, match="robot_or_radius"):
        mc.reference_landmarks(-1.0)


# --- registration ------------------------------------------------------------------------


def test_registration_recovers_a_transform_exactly_without_noise() -> None:
    rotation = Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix()
    translation = np.array([0.8, -0.4, 0.5])
    # camera points such that model = R camera + t
    camera = (LANDMARKS - translation) @ rotation
    reg = mc.rigid_registration(camera, LANDMARKS)
    np.testing.assert_allclose(reg.rotation, rotation, atol=1e-12)
    np.testing.assert_allclose(reg.translation_mm * MM, translation, atol=1e-12)
    assert reg.rms_mm * MM < 1e-12
    assert reg.residuals_mm.shape == (8,)
    np.testing.assert_allclose(mc.to_manipulator_frame(reg, camera), LANDMARKS, atol=1e-12)
    np.testing.assert_allclose(mc.to_manipulator_frame(reg, camera[0]), LANDMARKS[0], atol=1e-12)
    homogeneous = np.column_stack([camera / MM, np.ones(8)]) @ reg.matrix_mm.T
    np.testing.assert_allclose(homogeneous[:, :3] * MM, LANDMARKS, atol=1e-12)


@pytest.mark.parametrize(("sigma_camera", "sigma_model"), [(0.5 * MM, 0.0), (0.4 * MM, 0.3 * MM)])
def test_registration_rms_error_matches_the_noise(sigma_camera: float, sigma_model: float) -> None:
    """E[RMS²] = 3 σ_eff² (N − 2) / N: 3N noise degrees of freedom, 6 taken by the fit.

    σ_eff² = σ_C² + σ_M²; both cases have σ_eff = 0.5 mm, so for N = 8 the expected RMS
    is 0.5 mm · sqrt(3 · 6 / 8) = 0.75 mm. Over 400 registrations the mean of RMS² has
    a relative standard deviation of sqrt(2 / 18) / sqrt(400) = 1.7 %: a ±6 % band on it
    (±3 % on its square root) is about 3.5 standard deviations.
    """
    rng = np.random.default_rng(20240601)
    n = len(LANDMARKS)
    sigma_eff2 = sigma_camera**2 + sigma_model**2
    expected = np.sqrt(3 * sigma_eff2 * (n - 2) / n)
    squares = []
    for _ in range(400):
        rotation = Rotation.random(random_state=rng).as_matrix()
        translation = rng.uniform(-1.0, 1.0, 3)
        camera = (LANDMARKS - translation) @ rotation + sigma_camera * rng.standard_normal((n, 3))
        model = LANDMARKS + sigma_model * rng.standard_normal((n, 3))
        reg = mc.rigid_registration(camera, model)
        np.testing.assert_allclose(reg.rms_mm, np.sqrt(np.mean(reg.residuals_mm**2)))
        squares.append((reg.rms_mm * MM) ** 2)
    measured = np.sqrt(np.mean(squares))
    assert expected == pytest.approx(0.75 * MM)
    assert measured == pytest.approx(expected, rel=0.03)


def _well_spread(points: np.ndarray, rank: int) -> bool:
    singular = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(singular[rank - 1] > 1e-2 * singular[0] and singular[0] > 0.05)


_points = st.integers(3, 12).flatmap(
    lambda n: arrays(np.float64, (n, 3), elements=st.floats(-0.5, 0.5, allow_subnormal=False))
)
_quaternions = arrays(np.float64, 4, elements=st.floats(-1.0, 1.0)).filter(
    lambda q: np.linalg.norm(q) > 0.1
)
_translations = arrays(np.float64, 3, elements=st.floats(-2.0, 2.0))


@settings(max_examples=60, deadline=None)
@given(model=_points, quaternion=_quaternions, translation=_translations)
def test_any_rigid_transform_is_recovered_exactly(
    model: np.ndarray, quaternion: np.ndarray, translation: np.ndarray
) -> None:
    assume(_well_spread(model, rank=2))  # not collinear
    rotation = Rotation.from_quat(quaternion).as_matrix()
    camera = (model - translation) @ rotation
    reg = mc.rigid_registration(camera, model)
    np.testing.assert_allclose(reg.rotation, rotation, atol=1e-12)
    np.testing.assert_allclose(reg.translation_mm * MM, translation, atol=1e-12)
    assert reg.rms_mm * MM < 1e-12


@settings(max_examples=60, deadline=None)
@given(model=_points, quaternion=_quaternions, translation=_translations)
def test_the_rotation_is_proper_even_when_a_reflection_fits_exactly(
    model: np.ndarray, quaternion: np.ndarray, translation: np.ndarray
) -> None:
    assume(len(model) >= 4 and _well_spread(model, rank=3))  # not coplanar
    mirror = Rotation.from_quat(quaternion).as_matrix() @ np.diag([1.0, 1.0, -1.0])
    camera = model @ mirror + translation  # an improper map takes camera onto model
    reg = mc.rigid_registration(camera, model)
    np.testing.assert_allclose(reg.rotation @ reg.rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(reg.rotation) == pytest.approx(1.0, abs=1e-12)
    assert reg.rms_mm > 0.0  # no proper rotation maps a non-coplanar set onto its mirror
    # ... and it is the best proper rotation: scipy's align_vectors finds no better one
    centred_c, centred_m = camera - camera.mean(axis=0), model - model.mean(axis=0)
    other, _ = Rotation.align_vectors(centred_m, centred_c)
    other_rms = np.sqrt(np.mean(np.sum((other.apply(centred_c) - centred_m) ** 2, axis=1)))
    assert reg.rms_mm * MM <= other_rms + 1e-12


_GOOD = LANDMARKS[:4]


@pytest.mark.parametrize(
    ("camera", "model", "argument", "what"),
    [
        (_GOOD[:, :2], _GOOD, "camera_points", "shape"),
        (_GOOD, _GOOD.ravel(), "model_points", "shape"),
        (_GOOD[:2], _GOOD[:2], "camera_points", "at least 3"),
        (_GOOD, _GOOD[:3], "model_points", "expected 4"),
        (np.where(np.eye(4, 3, dtype=bool), np.nan, _GOOD), _GOOD, "camera_points", "finite"),
        (_GOOD, np.full((4, 3), np.inf), "model_points", "finite"),
        ([["a", "b", "c"]] * 4, _GOOD, "camera_points", "numbers"),
        (np.outer([0.0, 1.0, 2.0, 3.0], [0.1, 0.2, 0.3]), _GOOD, "camera_points", "collinear"),
        (_GOOD, np.ones((4, 3)), "model_points", "coincide"),
    ],
)
def test_bad_registration_input_names_the_argument(
    camera: object, model: object, argument: str, what: str
) -> None:
    with pytest.raises(InputError, match=argument) as caught:
        mc.rigid_registration(camera, model)
    message = str(caught.value)
    assert what in message
    assert "\n" not in message


def test_apply_checks_its_input() -> None:
    reg = mc.rigid_registration(LANDMARKS, LANDMARKS)
    with pytest.raises(InputError, match="points_c"):
        mc.to_manipulator_frame(reg, np.zeros((5, 2)))


# --- path deviation ----------------------------------------------------------------------


def _brute_force_distances(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Every point against every segment, written independently of the module."""
    best = np.full(len(points), np.inf)
    for a, b in zip(path[:-1], path[1:], strict=True):
        ab = b - a
        length2 = ab @ ab
        t = np.zeros(len(points)) if length2 == 0 else np.clip((points - a) @ ab / length2, 0, 1)
        best = np.minimum(best, np.linalg.norm(points - (a + t[:, None] * ab), axis=1))
    return best


def test_straight_path_offset_by_a_known_distance() -> None:
    desired = np.column_stack([np.linspace(0.0, 1.0, 11), np.zeros(11), np.zeros(11)])
    x = np.linspace(0.0, 1.0, 101)
    tracked = np.column_stack([x, np.full_like(x, 3 * MM), np.full_like(x, 4 * MM)])
    deviation = mc.path_deviation(tracked, desired)
    assert deviation.centroid_distance_mm == pytest.approx(5.0)
    assert deviation.rms_distance_mm == pytest.approx(5.0)
    assert deviation.max_distance_mm == pytest.approx(5.0)
    assert deviation.to_dict() == {
        "centroid_distance_mm": deviation.centroid_distance_mm,
        "rms_distance_mm": deviation.rms_distance_mm,
        "max_distance_mm": deviation.max_distance_mm,
    }


def test_closest_point_distances_by_hand() -> None:
    # an L: (0,0,0) -> (1,0,0) -> (1,1,0)
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    points = np.array(
        [
            [0.5, -0.2, 0.0],  # below the first leg: 0.2
            [0.9, 0.5, 0.0],  # inside the corner: 0.1 from the second leg
            [1.3, 1.4, 0.0],  # past the end: |(0.3, 0.4)| = 0.5
            [-0.3, 0.0, 0.4],  # before the start: |(0.3, 0, 0.4)| = 0.5
            [1.0, 0.0, 0.0],  # on the corner: 0
        ]
    )
    distances = mc.closest_point_distances(points, path)
    np.testing.assert_allclose(distances, [0.2, 0.1, 0.5, 0.5, 0.0], atol=1e-15)
    # a path of one point is that point
    single = mc.closest_point_distances(points, path[:1])
    np.testing.assert_allclose(single, np.linalg.norm(points, axis=1))


def test_centroid_distance_of_shifted_sets() -> None:
    rng = np.random.default_rng(7)
    tracked = rng.uniform(-0.1, 0.1, (200, 3))
    shift = np.array([0.3, -0.2, 0.6]) * MM
    deviation = mc.path_deviation(tracked, tracked + shift)
    assert deviation.centroid_distance_mm == pytest.approx(0.7)
    assert deviation.max_distance_mm <= 0.7 + 1e-9


@pytest.mark.parametrize("seed", range(6))
def test_closest_point_distances_match_brute_force(seed: int) -> None:
    """Including repeated vertices (dwell), one very long segment and far-off points."""
    rng = np.random.default_rng(seed)
    path = np.cumsum(rng.normal(0.0, 1 * MM, (300, 3)), axis=0)
    path = np.repeat(path, rng.integers(1, 4, len(path)), axis=0)
    path[-1] += [0.3, 0.0, 0.0]  # a last segment about 1000 times the others
    near = path[rng.integers(0, len(path), 300)] + rng.normal(0.0, 2 * MM, (300, 3))
    far = rng.normal(0.0, 0.5, (20, 3))
    points = np.vstack([near, far])
    np.testing.assert_allclose(
        mc.closest_point_distances(points, path),
        _brute_force_distances(points, path),
        rtol=1e-12,
        atol=1e-15,
    )


def test_deviation_runs_on_ten_thousand_points() -> None:
    times, desired = _circle_path(10_000)
    rng = np.random.default_rng(1)
    tracked = desired + rng.normal(0.0, 0.5 * MM, desired.shape)
    deviation = mc.path_deviation(tracked, desired)
    # the normal part of isotropic noise off a curve is 2-D: RMS about σ sqrt(2)
    assert deviation.rms_distance_mm == pytest.approx(0.5 * np.sqrt(2), rel=0.03)


def test_deviation_rejects_bad_paths() -> None:
    with pytest.raises(InputError, match="tracked_m"):
        mc.path_deviation(np.full((3, 3), np.nan), LANDMARKS)
    with pytest.raises(InputError, match="desired_m"):
        mc.path_deviation(LANDMARKS, np.zeros((0, 3)))


# --- synthetic capture and the whole pipeline --------------------------------------------


def test_capture_is_seeded_and_its_noise_in_range() -> None:
    times, path = _circle_path()
    first = mc.synthetic_capture(LANDMARKS, times, path, rng=5)
    again = mc.synthetic_capture(LANDMARKS, times, path, rng=5)
    np.testing.assert_array_equal(first.marker_c, again.marker_c)
    np.testing.assert_array_equal(first.landmarks_c, again.landmarks_c)
    sigmas = [mc.synthetic_capture(LANDMARKS, times, path, rng=s).noise_std_m for s in range(30)]
    assert 0.3 * MM <= min(sigmas) < max(sigmas) <= 0.6 * MM
    assert np.linalg.norm(first.true_translation) <= 1.0
    assert np.linalg.det(first.true_rotation) == pytest.approx(1.0)


def test_noiseless_capture_registers_exactly() -> None:
    times, path = _circle_path()
    capture = mc.synthetic_capture(LANDMARKS, times, path, rng=11, noise_std_m=0.0)
    reg = mc.rigid_registration(capture.landmarks_c, LANDMARKS)
    np.testing.assert_allclose(reg.rotation, capture.true_rotation, atol=1e-12)
    np.testing.assert_allclose(reg.translation_mm * MM, capture.true_translation, atol=1e-12)
    np.testing.assert_allclose(mc.to_manipulator_frame(reg, capture.marker_c), path, atol=1e-12)


def test_round_trip_error_matches_noise_and_target_registration_error() -> None:
    """Mapped marker error² = marker noise 3σ² + TRE² (Fitzpatrick et al. 1998).

    TRE²(r) ≈ (3σ² / N) (1 + ⅓ Σ_k d_k² / f_k²): d_k the target's distance from the k-th
    principal axis of the landmarks, f_k the landmarks' RMS distance from it. The path
    is 150 mm above the landmarks, so TRE is about 0.9 σ there and the mapped points
    are off by about 1.96 σ RMS, not √3 σ. Averaged over 200 captures.
    """
    sigma = 0.5 * MM
    times, path = _circle_path()
    n = len(LANDMARKS)
    centred = LANDMARKS - LANDMARKS.mean(axis=0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    target = path - LANDMARKS.mean(axis=0)
    f2 = np.sum(centred**2, axis=1).mean() - np.mean((centred @ axes) ** 2, axis=0)
    d2 = np.sum(target**2, axis=1)[:, None] - (target @ axes) ** 2
    tre2 = 3 * sigma**2 / n * (1 + np.sum(d2 / f2, axis=1) / 3)
    expected = np.sqrt(3 * sigma**2 + tre2.mean())

    squares = []
    for seed in range(200):
        capture = mc.synthetic_capture(LANDMARKS, times, path, rng=seed, noise_std_m=sigma)
        reg = mc.rigid_registration(capture.landmarks_c, LANDMARKS)
        error = mc.to_manipulator_frame(reg, capture.marker_c) - path
        squares.append(np.mean(np.sum(error**2, axis=1)))
    assert np.sqrt(np.mean(squares)) == pytest.approx(expected, rel=0.05)
    assert expected / sigma == pytest.approx(1.96, abs=0.05)


def test_synthetic_capture_rejects_bad_input() -> None:
    times, path = _circle_path()
    with pytest.raises(InputError, match="marker_times_s"):
        mc.synthetic_capture(LANDMARKS, times[:-1], path)
    with pytest.raises(InputError, match="marker_times_s"):
        mc.synthetic_capture(LANDMARKS, times[::-1], path)
    with pytest.raises(InputError, match="noise_std_m"):
        mc.synthetic_capture(LANDMARKS, times, path, noise_std_m=(0.6 * MM, 0.3 * MM))
    with pytest.raises(InputError, match="noise_std_m"):
        mc.synthetic_capture(LANDMARKS, times, path, noise_std_m=-1.0)
    with pytest.raises(InputError, match="landmarks_m"):
        mc.synthetic_capture(LANDMARKS[:, :2], times, path)


# --- CSV files ---------------------------------------------------------------------------


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_read_capture_csv_skips_and_counts_occluded_rows(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "capture.csv",
        "time_s,x_mm,y_mm,z_mm\n"
        "0.00,1.0,2.0,3.0\n"
        "0.01,,,\n"
        "0.02, 1.5 ,2.5,3.5\n"
        "\n"
        "0.03,,,\n"
        "0.04,2.0,3.0,4.0\n",
    )
    times, points = mc.read_capture_csv(path)
    np.testing.assert_allclose(times, [0.0, 0.02, 0.04])
    np.testing.assert_allclose(
        points, [[1e-3, 2e-3, 3e-3], [1.5e-3, 2.5e-3, 3.5e-3], [2e-3, 3e-3, 4e-3]]
    )
    track = mc.read_capture_csv(str(path))
    assert track.occluded_lines == (3, 6)
    assert track.n_occluded == 2
    assert track.points_m.shape == (3, 3)
    assert track.times_s is track[0]
    copied = pickle.loads(pickle.dumps(track))
    assert copied.occluded_lines == (3, 6)
    np.testing.assert_array_equal(copied.points_m, track.points_m)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("time_s,x_mm,y_mm\n0,1,2\n", "line 1: column z_mm is missing"),
        ("t,x,y,z\n0,1,2,3\n", "line 1: column time_s is missing"),
        ("x_mm,time_s,y_mm,z_mm\n1,0,2,3\n", "line 1: header is 'x_mm,time_s,y_mm,z_mm'"),
        ("", "empty file"),
        ("time_s,x_mm,y_mm,z_mm\n0,1,2,3\n0.1,1,abc,3\n", "line 3, column y_mm = 'abc'"),
        ("time_s,x_mm,y_mm,z_mm\n0,1,2,3\n0.1,1,,3\n", "line 3, column y_mm = ''"),
        ("time_s,x_mm,y_mm,z_mm\n0,1,2,3\n0.1,1,2\n", "line 3, column z_mm missing"),
        ("time_s,x_mm,y_mm,z_mm\n0,1,2,3,4\n", "line 2, column z_mm has extra cells"),
        ("time_s,x_mm,y_mm,z_mm\n,1,2,3\n", "line 2, column time_s = ''"),
        ("time_s,x_mm,y_mm,z_mm\n0,1,2,nan\n", "line 2, column z_mm = 'nan'"),
        ("time_s,x_mm,y_mm,z_mm\n0.1,1,2,3\n0.1,1,2,3\n", "line 3, column time_s = '0.1'"),
        ("time_s,x_mm,y_mm,z_mm\n0,,,\n0.1,,,\n", "no frame with the marker (2 occluded)"),
    ],
)
def test_read_capture_csv_rejects_bad_files(tmp_path: Path, text: str, expected: str) -> None:
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(InputError) as caught:
        mc.read_capture_csv(path)
    message = str(caught.value)
    assert message.startswith(str(path))
    assert expected in message
    assert "\n" not in message


def test_read_capture_csv_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        mc.read_capture_csv(tmp_path / "absent.csv")


def test_read_landmarks_csv(tmp_path: Path) -> None:
    path = _write(tmp_path / "landmarks.csv", "name,x_mm,y_mm,z_mm\nL1,190,0,0\nL2,0,190,-38\n")
    names, points = mc.read_landmarks_csv(path)
    assert names == ("L1", "L2")
    np.testing.assert_allclose(points, [[0.19, 0.0, 0.0], [0.0, 0.19, -0.038]])


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("name,x_mm,y_mm\nL1,1,2\n", "column z_mm is missing"),
        ("name,x_mm,y_mm,z_mm\nL1,1,2,\n", "line 2, column z_mm = ''"),
        ("name,x_mm,y_mm,z_mm\n,1,2,3\n", "line 2, column name is empty"),
        ("name,x_mm,y_mm,z_mm\nL1,1,2,3\nL1,4,5,6\n", "line 3, column name = 'L1'"),
        ("name,x_mm,y_mm,z_mm\n", "no landmark"),
    ],
)
def test_read_landmarks_csv_rejects_bad_files(tmp_path: Path, text: str, expected: str) -> None:
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(InputError, match="bad.csv") as caught:
        mc.read_landmarks_csv(path)
    assert expected in str(caught.value)


def test_files_to_deviation(tmp_path: Path) -> None:
    """Synthetic capture written as the cameras' files, read back, registered, compared."""
    times, path = _circle_path()
    capture = mc.synthetic_capture(LANDMARKS, times, path, rng=3)
    lines = ["name,x_mm,y_mm,z_mm"]
    lines += [
        f"P{i + 1},{x:.4f},{y:.4f},{z:.4f}" for i, (x, y, z) in enumerate(capture.landmarks_c / MM)
    ]
    landmarks_file = _write(tmp_path / "landmarks_c.csv", "\n".join(lines) + "\n")
    rows = ["time_s,x_mm,y_mm,z_mm"]
    for k, (t, (x, y, z)) in enumerate(zip(times, capture.marker_c / MM, strict=True)):
        rows.append(f"{t:.4f},,," if k % 10 == 5 else f"{t:.4f},{x:.4f},{y:.4f},{z:.4f}")
    capture_file = _write(tmp_path / "marker_c.csv", "\n".join(rows) + "\n")

    _, landmarks_c = mc.read_landmarks_csv(landmarks_file)
    track = mc.read_capture_csv(capture_file)
    assert track.n_occluded == 40
    reg = mc.rigid_registration(landmarks_c, LANDMARKS)
    assert reg.rms_mm * MM < 3 * capture.noise_std_m
    deviation = mc.path_deviation(mc.to_manipulator_frame(reg, track.points_m), path)
    assert deviation.rms_distance_mm < 3 * capture.noise_std_m / MM
    assert deviation.centroid_distance_mm < 3 * capture.noise_std_m / MM
