"""Kinematics of the SPM (paper Eqs. 1, 2, 5, 13, 14, 17, 18) against independent checks.

The references are independent of the code under test: round trips between the forward
and inverse maps, the paper's constraint equations and printed matrix entries, finite
differences, CasADi's automatic differentiation, numpy's SVD, and Table III's numbers.
"""

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from spm_opt.base.errors import UnreachableError
from spm_opt.model import kinematics as kin
from spm_opt.model.params import load_robot

ROOT = Path(__file__).resolve().parents[1]
PROTOTYPE = ROOT / "problems" / "robots" / "prototype.toml"
R_U = 0.17133  # m, Table III
LIMIT = np.radians(60.0)  # the prototype's joint range, rad
MM = 1e-3

FAST = settings(max_examples=60, deadline=None)
FEW = settings(max_examples=25, deadline=None)

angle = st.floats(-LIMIT, LIMIT, allow_nan=False, allow_infinity=False)
rate = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)
joint_angles = st.tuples(angle, angle).map(np.array)
joint_rates = st.tuples(rate, rate).map(np.array)
angle_batches = hnp.arrays(
    np.float64,
    st.tuples(st.integers(1, 300), st.just(2)),
    elements=st.floats(-LIMIT, LIMIT, allow_nan=False, allow_infinity=False),
)


@st.composite
def platform_points(draw: st.DrawFn) -> np.ndarray:
    """A point r_u * u with u a unit vector of u_z >= 0.3 (cone of half-angle ~72.5°)."""
    z = draw(st.floats(0.3, 1.0))
    azimuth = draw(st.floats(0.0, 2.0 * np.pi))
    rho = np.sqrt(1.0 - z * z)
    return R_U * np.array([rho * np.cos(azimuth), rho * np.sin(azimuth), z])


def skew_vector(w: np.ndarray) -> np.ndarray:
    """The vector of the skew-symmetric part of 3x3 matrices w (..., 3, 3)."""
    return 0.5 * np.stack(
        [w[..., 2, 1] - w[..., 1, 2], w[..., 0, 2] - w[..., 2, 0], w[..., 1, 0] - w[..., 0, 1]],
        axis=-1,
    )


# --- 1, 2: inverse and forward kinematics are each other's inverse --------------------


@FAST
@given(q=joint_angles)
def test_inverse_of_forward_is_identity(q):
    b = kin.forward_kinematics(q[None, :], R_U)
    assert b.shape == (1, 3)
    q_back = kin.inverse_kinematics(b)
    assert q_back.shape == (1, 2)
    np.testing.assert_allclose(q_back[0], q, rtol=0, atol=1e-12)


@FEW
@given(q=angle_batches)
def test_inverse_of_forward_is_identity_vectorised(q):
    b = kin.forward_kinematics(q, R_U)
    assert b.shape == (len(q), 3)
    np.testing.assert_allclose(kin.inverse_kinematics(b), q, rtol=0, atol=1e-12)


def test_forward_kinematics_known_configurations():
    """θ = 0: straight up; θ2 alone tilts B towards +x, θ1 alone towards −y (Eq. 5)."""
    q = np.radians([[0.0, 0.0], [0.0, 30.0], [30.0, 0.0]])
    expected = R_U * np.array(
        [[0.0, 0.0, 1.0], [0.5, 0.0, np.sqrt(3) / 2], [0.0, -0.5, np.sqrt(3) / 2]]
    )
    np.testing.assert_allclose(kin.forward_kinematics(q, R_U), expected, rtol=0, atol=1e-15)


@FAST
@given(b=platform_points())
def test_forward_of_inverse_is_identity(b):
    q = kin.inverse_kinematics(b[None, :])
    np.testing.assert_allclose(kin.forward_kinematics(q, R_U)[0], b, rtol=0, atol=1e-12)


@FEW
@given(points=st.lists(platform_points(), min_size=1, max_size=100))
def test_forward_of_inverse_is_identity_vectorised(points):
    b = np.array(points)
    q = kin.inverse_kinematics(b)
    assert q.shape == (len(b), 2)
    np.testing.assert_allclose(kin.forward_kinematics(q, R_U), b, rtol=0, atol=1e-12)


# --- 3: forward kinematics on the sphere and on the paper's constraint surfaces -------


@FEW
@given(q=angle_batches)
def test_forward_kinematics_satisfies_sphere_and_constraints_13_14(q):
    b = kin.forward_kinematics(q, R_U)
    theta1, theta2 = q[:, 0], q[:, 1]
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), R_U, rtol=1e-14, atol=0)
    gamma2 = b[:, 1] * np.cos(theta1) + b[:, 2] * np.sin(theta1)
    gamma3 = b[:, 0] * np.cos(theta2) - b[:, 2] * np.sin(theta2)
    np.testing.assert_allclose(gamma2, 0.0, atol=1e-15)
    np.testing.assert_allclose(gamma3, 0.0, atol=1e-15)
    assert np.all(b[:, 2] > 0.0)


# --- 4: Eq. 1 projection --------------------------------------------------------------


def test_projection_of_papers_landmark_a2():
    a2 = np.array([[-22.14, -11.39, 63.10]]) * MM
    b2 = kin.project_landmarks(a2, R_U)
    np.testing.assert_allclose(b2[0], np.array([-55.919, -28.768, 159.372]) * MM, atol=6e-7)
    assert np.linalg.norm(b2[0]) == pytest.approx(R_U, rel=1e-14)


def test_projection_of_all_table_iii_landmarks():
    """Table III prints B_i to 0.01 mm (truncated), so compare to within 0.01 mm."""
    a = np.array(
        [[0.0, 0.0, 68.08], [-22.14, -11.39, 63.10], [-32.44, 22.58, 60.42], [-6.69, 23.32, 66.35]]
    )
    b_table = np.array(
        [
            [0.0, 0.0, 171.33],
            [-55.91, -28.77, 159.37],
            [-76.98, 53.58, 143.37],
            [-16.22, 56.55, 160.91],
        ]
    )
    b = kin.project_landmarks(a * MM, R_U) / MM
    np.testing.assert_allclose(b, b_table, rtol=0, atol=0.01)


@FAST
@given(
    a=hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0)).filter(
        lambda v: np.linalg.norm(v) > 1e-3
    ),
    factor=st.floats(1e-3, 1e3),
)
def test_projection_is_scale_invariant_and_on_the_sphere(a, factor):
    b = kin.project_landmarks(np.stack([a, factor * a, 2.0 * a]), R_U)
    np.testing.assert_allclose(b[1], b[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(b[2], b[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), R_U, rtol=1e-14)
    # Radial: B is a positive multiple of A.
    np.testing.assert_allclose(np.cross(b[0], a), 0.0, atol=1e-15)
    assert np.dot(b[0], a) > 0.0


# --- 5: Eq. 17 frames -----------------------------------------------------------------


@FEW
@given(q=angle_batches)
def test_frames_are_rotations_matching_eq_17(q):
    upper, lower = kin.platform_frames(q)
    n = len(q)
    assert upper.shape == lower.shape == (n, 3, 3)
    b = kin.forward_kinematics(q, R_U)
    bx, by, bz = b[:, 0], b[:, 1], b[:, 2]
    c1, s1, c2, s2 = np.cos(q[:, 0]), np.sin(q[:, 0]), np.cos(q[:, 1]), np.sin(q[:, 1])
    zero, eye = np.zeros(n), np.broadcast_to(np.eye(3), (n, 3, 3))
    for r in (upper, lower):
        np.testing.assert_allclose(np.swapaxes(r, -1, -2) @ r, eye, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(r), 1.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(r[:, :, 2], b / R_U, rtol=0, atol=1e-14)
    np.testing.assert_allclose(upper[:, :, 1], np.stack([zero, c1, s1], -1), atol=1e-15)
    np.testing.assert_allclose(lower[:, :, 0], np.stack([c2, zero, -s2], -1), atol=1e-15)
    # The paper's printed entries of Eq. 17.
    upper_x = np.stack([(c1 * bz - s1 * by) / R_U, s1 * bx / R_U, -c1 * bx / R_U], -1)
    lower_y = np.stack([-s2 * by / R_U, (c2 * bz + s2 * bx) / R_U, -c2 * by / R_U], -1)
    np.testing.assert_allclose(upper[:, :, 0], upper_x, rtol=0, atol=1e-14)
    np.testing.assert_allclose(lower[:, :, 1], lower_y, rtol=0, atol=1e-14)


def test_frames_at_home_are_identity():
    upper, lower = kin.platform_frames(np.zeros((1, 2)))
    np.testing.assert_allclose(upper[0], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(lower[0], np.eye(3), atol=1e-15)


# --- 6: Eq. 18 angular velocities -----------------------------------------------------


@FAST
@given(q=joint_angles, qd=joint_rates)
def test_angular_velocities_match_finite_differences_of_frames(q, qd):
    h = 1e-6
    w_upper, w_lower = kin.platform_angular_velocities(q[None, :], qd[None, :])
    assert w_upper.shape == w_lower.shape == (1, 3)
    plus = kin.platform_frames((q + h * qd)[None, :])
    minus = kin.platform_frames((q - h * qd)[None, :])
    here = kin.platform_frames(q[None, :])
    for w, r_plus, r_minus, r in zip((w_upper, w_lower), plus, minus, here, strict=True):
        r_dot = (r_plus[0] - r_minus[0]) / (2 * h)
        s = r_dot @ r[0].T
        np.testing.assert_allclose(s, -s.T, atol=1e-7)  # Ṙ Rᵀ is skew-symmetric
        np.testing.assert_allclose(w[0], skew_vector(s), rtol=0, atol=1e-7)


@FAST
@given(q=joint_angles, qd=joint_rates)
def test_upper_angular_velocity_moves_b(q, qd):
    """B is fixed in the upper platform (its z axis), so Ḃ = ω_u × B = (dB/dθ) θ̇."""
    w_upper, w_lower = kin.platform_angular_velocities(q[None, :], qd[None, :])
    b = kin.forward_kinematics(q[None, :], R_U)[0]
    b_dot = kin.platform_jacobian(q[None, :], R_U)[0] @ qd
    np.testing.assert_allclose(np.cross(w_upper[0], b), b_dot, rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.cross(w_lower[0], b), b_dot, rtol=0, atol=1e-13)


def test_angular_velocity_at_home_is_the_input_rates():
    """At θ = 0 the platforms turn with the arcs: ω = (θ̇1, θ̇2, 0)."""
    w_upper, w_lower = kin.platform_angular_velocities(np.zeros((1, 2)), np.array([[0.3, -0.7]]))
    np.testing.assert_allclose(w_upper[0], [0.3, -0.7, 0.0], atol=1e-15)
    np.testing.assert_allclose(w_lower[0], [0.3, -0.7, 0.0], atol=1e-15)


# --- 7: Jacobian: finite differences and CasADi's automatic differentiation -----------


@FEW
@given(q=angle_batches)
def test_jacobian_matches_finite_differences(q):
    h = 1e-6
    jac = kin.platform_jacobian(q, R_U)
    assert jac.shape == (len(q), 3, 2)
    for k in range(2):
        step = np.zeros(2)
        step[k] = h
        fd = (kin.forward_kinematics(q + step, R_U) - kin.forward_kinematics(q - step, R_U)) / (
            2 * h
        )
        np.testing.assert_allclose(jac[:, :, k], fd, rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def symbolic_functions():
    s = kin.symbolic()
    assert s.q.shape == (2, 1) and s.qd.shape == (2, 1)
    # Ṙ = Σ_k ∂R/∂q_k q̇_k by CasADi's AD, for an AD-derived angular velocity.
    ad_rates = [
        ca.reshape(ca.jacobian(ca.vec(r), s.q) @ s.qd, 3, 3) for r in (s.upper_frame, s.lower_frame)
    ]
    return {
        "direction": ca.Function(
            "direction", [s.q], [s.direction, ca.jacobian(s.direction, s.q), s.direction_jacobian]
        ),
        "frames": ca.Function(
            "frames",
            [s.q, s.qd],
            [
                s.upper_frame,
                s.lower_frame,
                s.upper_angular_velocity,
                s.lower_angular_velocity,
                *ad_rates,
            ],
        ),
    }


@FAST
@given(q=joint_angles)
def test_symbolic_jacobian_equals_casadi_ad(symbolic_functions, q):
    direction, ad_jac, written_jac = (np.array(v) for v in symbolic_functions["direction"](q))
    assert ad_jac.shape == written_jac.shape == (3, 2)
    np.testing.assert_allclose(written_jac, ad_jac, rtol=0, atol=1e-14)
    np.testing.assert_allclose(direction[:, 0], kin.forward_kinematics(q, R_U) / R_U, atol=1e-15)
    np.testing.assert_allclose(ad_jac * R_U, kin.platform_jacobian(q, R_U), rtol=0, atol=1e-15)


@FAST
@given(q=joint_angles, qd=joint_rates)
def test_symbolic_frames_and_velocities_equal_numpy(symbolic_functions, q, qd):
    out = [np.array(v) for v in symbolic_functions["frames"](q, qd)]
    upper, lower, w_upper, w_lower, upper_dot, lower_dot = out
    np_upper, np_lower = kin.platform_frames(q[None, :])
    np_w_upper, np_w_lower = kin.platform_angular_velocities(q[None, :], qd[None, :])
    np.testing.assert_allclose(upper, np_upper[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(lower, np_lower[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(w_upper[:, 0], np_w_upper[0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(w_lower[:, 0], np_w_lower[0], rtol=0, atol=1e-14)
    # Angular velocity from CasADi's derivative of the frames, [ω]× = Ṙ Rᵀ.
    np.testing.assert_allclose(w_upper[:, 0], skew_vector(upper_dot @ upper.T), atol=1e-13)
    np.testing.assert_allclose(w_lower[:, 0], skew_vector(lower_dot @ lower.T), atol=1e-13)


# --- 8: singularity margin ------------------------------------------------------------


def test_singularity_margin_is_one_at_home():
    assert kin.singularity_margins(np.zeros((1, 2)))[0] == pytest.approx(1.0, abs=1e-15)


@FEW
@given(q=angle_batches)
def test_singularity_margin_is_smallest_singular_value(q):
    margins = kin.singularity_margins(q)
    assert margins.shape == (len(q),)
    sigma = np.linalg.svd(kin.platform_jacobian(q, 1.0), compute_uv=False)
    np.testing.assert_allclose(margins, sigma[:, -1], rtol=0, atol=1e-7)
    # The prototype's notes: at least 0.5 everywhere in the ±60° box.
    assert np.all(margins >= 0.5)


@FAST
@given(theta1=angle)
def test_singularity_margin_vanishes_at_the_isocenter_plane(theta1):
    theta2 = np.radians([60.0, 80.0, 89.0, 89.9, 89.99])
    q = np.stack([np.full_like(theta2, theta1), theta2], axis=-1)
    margins = kin.singularity_margins(q)
    assert np.all(np.diff(margins) < 0)
    # It vanishes linearly in cos θ2 (= B_z / r_u at θ1 = 0): between ½ and 1/C1 times it.
    ratio = margins / np.cos(theta2)
    assert np.all(ratio >= 0.5)
    assert np.all(ratio <= (1 + 1e-6) / np.cos(theta1))
    assert margins[-2] < 4e-3  # θ2 = 89.9°
    assert margins[-1] < 4e-4


def test_singularity_margin_along_theta2_is_cos_theta2():
    """At θ1 = 0, b = (S2, 0, C2): the columns have norms C2 and 1, and are orthogonal."""
    theta2 = np.radians([0.0, 30.0, 60.0, 89.0, 89.9])
    q = np.stack([np.zeros_like(theta2), theta2], axis=-1)
    np.testing.assert_allclose(kin.singularity_margins(q), np.cos(theta2), rtol=1e-9)


# --- 9: inverse kinematics refuses points at or below the isocenter plane -------------


@pytest.mark.parametrize("bz", [0.0, -1e-9, -0.05, -R_U])
def test_inverse_kinematics_rejects_nonpositive_bz(bz):
    points = np.array([[0.0, 0.0, R_U], [0.05, -0.02, bz]])
    with pytest.raises(UnreachableError, match="B_z") as info:
        kin.inverse_kinematics(points)
    assert "point 1" in str(info.value)


def test_inverse_kinematics_accepts_points_just_above_the_plane():
    q = kin.inverse_kinematics(np.array([[0.0, 0.0, R_U], [0.0, 0.1, 1e-12]]))
    assert np.all(np.isfinite(q))


# --- 10: the robot's reachability checks ----------------------------------------------


@pytest.fixture(scope="module")
def robot():
    return load_robot(PROTOTYPE)


def test_prototype_robot_geometry(robot):
    assert robot.upper_platform_radius == pytest.approx(R_U, rel=1e-12)
    np.testing.assert_allclose(robot.joint_range, [[-LIMIT, LIMIT], [-LIMIT, LIMIT]], rtol=1e-15)


def test_check_reachable_returns_inverse_kinematics_of_paper_landmarks(robot):
    a = np.array([[0.0, 0.0, 68.08], [-22.14, -11.39, 63.10], [-32.44, 22.58, 60.42]]) * MM
    b = kin.project_landmarks(a, R_U)
    q = robot.check_reachable(b, ["A1", "A2", "A3"])
    assert q.shape == (3, 2)
    np.testing.assert_allclose(q[:, 0], np.arctan2(-b[:, 1], b[:, 2]), atol=1e-15)
    np.testing.assert_allclose(q[:, 1], np.arctan2(b[:, 0], b[:, 2]), atol=1e-15)
    assert robot.unreachable_reason(q) == [None, None, None]


@pytest.mark.parametrize("q_deg", [(70.0, 0.0), (0.0, -65.0), (61.0, 61.0)])
def test_outside_joint_range_is_named(robot, q_deg):
    q = np.radians([[0.0, 0.0], q_deg])
    b = kin.forward_kinematics(q, R_U)
    with pytest.raises(UnreachableError, match="joint range") as info:
        robot.check_reachable(b, ["home", "far_landmark"])
    assert "far_landmark" in str(info.value)
    assert "home" not in str(info.value)
    reasons = robot.unreachable_reason(q)
    assert reasons[0] is None
    assert reasons[1] is not None and "joint range" in reasons[1]


@pytest.mark.parametrize("z", [0.0, -0.01])
def test_at_or_below_the_isocenter_plane_is_named(robot, z):
    b = np.array([[0.0, 0.0, R_U], [0.1, 0.02, z]])
    with pytest.raises(UnreachableError, match="isocenter") as info:
        robot.check_reachable(b, ["top", "low_point"])
    assert "low_point" in str(info.value)


def test_singularity_margin_stays_finite_next_to_the_singularity():
    """Within 1e-8 rad of θ2 = 90° the closed form must not cancel to a negative root."""
    theta2 = np.pi / 2 - np.geomspace(1e-4, 1e-9, 200)
    q = np.column_stack([np.full_like(theta2, -0.7818916710211435), theta2])
    margins = kin.singularity_margins(q)
    assert np.all(np.isfinite(margins)) and np.all(margins >= 0.0)
    smallest = np.linalg.svd(kin.platform_jacobian(q, 1.0), compute_uv=False)[:, -1]
    np.testing.assert_allclose(margins, smallest, rtol=1e-6, atol=1e-15)
