"""The robot as a MuJoCo multibody model: an independent check of the dynamics.

The model is generated from a :class:`~spm_opt.model.params.Robot` as two open chains from
the world, closed by one equality constraint:

- chain 1: hinge ``theta1`` about the base x axis carrying the upper arc (frame Rx(θ1),
  Eq. 16), then the passive hinge ``phi1`` about the arc's own y axis (the platform sliding
  on the rail, about N_u = Rx(θ1) ŷ) carrying the upper platform, whose frame is
  Rx(θ1) Ry(φ1) and whose mass centre is at r_u on its z axis;
- chain 2: hinge ``theta2`` about the base y axis carrying the lower arc (frame Ry(θ2)),
  then the passive hinge ``phi2`` about the arc's own x axis (about N_L = Ry(θ2) x̂) carrying
  the lower platform, frame Ry(θ2) Rx(φ2), mass centre at r_L on its z axis.

With the passive angles of :func:`passive_angles` these frames are exactly Eq. 17: the upper
platform keeps y_u = N_u and z_u = b, the lower one x_L = N_L and z_L = b.

Closing the loop: the revolute joint between the platforms has its axis on the radial line
through the isocenter and B. Both platforms already turn about the isocenter (every joint
axis passes through it), so their radial axes coincide as soon as one point of that axis
off the isocenter coincides. One ``connect`` constraint at B (anchor (0, 0, r_u) in the
upper platform's frame, the same point of the lower platform's frame at θ = φ = 0) does
that and leaves the rotation about the radial axis free, which is the revolute joint. Its
three rows have rank 2 (the radial row is identically zero: both points stay on the sphere
of radius r_u), which is the two closure conditions of the five-bar linkage; MuJoCo's
regularised solver takes the redundant row without trouble, and the inverse dynamics here
uses a least-squares solve (the torques are unique, the multipliers are not). A ``weld``
would also lock the rotation about the radial axis, so it does not fit.

No friction, damping, armature, joint limits or contacts. Gravity is −z with
``robot.gravity``. A payload is a point mass rigidly on the upper platform at
B + R_u·offset; it is merged into the upper platform's inertial element (parallel axes).

MuJoCo (``pip install mujoco``, the ``verify`` extra) is needed only by this module.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from functools import lru_cache

import casadi as ca
import numpy as np

from spm_opt.base.errors import require
from spm_opt.model.params import Body, Robot
from spm_opt.problem.trajectory import Trajectory

mujoco = require("mujoco", "the MuJoCo check (spm_opt.verify.multibody)")

ACTIVE_JOINTS = ("theta1", "theta2")
PASSIVE_JOINTS = ("phi1", "phi2")

# the loop closure in simulation: stiff and nearly hard (see simulate_open_loop)
EQUALITY_SOLREF = (2e-4, 1.0)
EQUALITY_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)


def _vector(values: np.ndarray | tuple[float, ...]) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.ravel(values))


def _fullinertia(inertia: np.ndarray) -> str:
    i = np.asarray(inertia, dtype=float)
    # MuJoCo's order: ixx iyy izz ixy ixz iyz
    return _vector((i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))


def _inertial(mass: float, position: np.ndarray, inertia: np.ndarray) -> str:
    return (
        f'<inertial pos="{_vector(position)}" mass="{float(mass):.17g}" '
        f'fullinertia="{_fullinertia(inertia)}"/>'
    )


def _body_inertial(body: Body) -> str:
    return _inertial(body.mass, np.array([0.0, 0.0, body.com_radius]), body.inertia)


def _upper_platform_inertial(robot: Robot) -> str:
    """The upper platform with the payload point mass merged in (parallel-axis theorem)."""
    body = robot.upper_platform
    mass_payload = float(robot.payload.mass)
    centre = np.array([0.0, 0.0, body.com_radius])
    if mass_payload == 0.0:
        return _body_inertial(body)
    point = centre + np.asarray(robot.payload.offset, dtype=float)
    mass = body.mass + mass_payload
    com = (body.mass * centre + mass_payload * point) / mass

    def shift(m: float, r: np.ndarray) -> np.ndarray:
        return m * (np.dot(r, r) * np.eye(3) - np.outer(r, r))

    inertia = (
        np.asarray(body.inertia, dtype=float)
        + shift(body.mass, centre - com)
        + shift(mass_payload, point - com)
    )
    return _inertial(mass, com, inertia)


def model_xml(robot: Robot) -> str:
    """The MJCF text of :func:`build_model` (see the module docstring)."""
    r_u = robot.upper_platform_radius
    joint = 'damping="0" armature="0" frictionloss="0" stiffness="0" limited="false"'
    return f"""<mujoco model="spm_{robot.name}">
  <compiler angle="radian" inertiafromgeom="false" balanceinertia="false"/>
  <option gravity="0 0 {-float(robot.gravity):.17g}" timestep="1e-4" integrator="RK4"
          jacobian="dense" cone="pyramidal">
    <flag contact="disable" energy="enable" frictionloss="disable"/>
  </option>
  <worldbody>
    <body name="upper_arc">
      <joint name="theta1" type="hinge" pos="0 0 0" axis="1 0 0" {joint}/>
      {_body_inertial(robot.upper_arc)}
      <body name="upper_platform">
        <joint name="phi1" type="hinge" pos="0 0 0" axis="0 1 0" {joint}/>
        {_upper_platform_inertial(robot)}
      </body>
    </body>
    <body name="lower_arc">
      <joint name="theta2" type="hinge" pos="0 0 0" axis="0 1 0" {joint}/>
      {_body_inertial(robot.lower_arc)}
      <body name="lower_platform">
        <joint name="phi2" type="hinge" pos="0 0 0" axis="1 0 0" {joint}/>
        {_body_inertial(robot.lower_platform)}
      </body>
    </body>
  </worldbody>
  <equality>
    <!-- the radial axes of both platforms coincide: the point B of both (see the module
         docstring); rotation about the radial axis stays free (the revolute joint) -->
    <connect name="loop" body1="upper_platform" body2="lower_platform"
             anchor="0 0 {r_u:.17g}" solref="{_vector(EQUALITY_SOLREF)}"
             solimp="{_vector(EQUALITY_SOLIMP)}"/>
  </equality>
</mujoco>
"""


def build_model(robot: Robot) -> mujoco.MjModel:
    """The robot as a MuJoCo model: two open chains closed by one ``connect`` constraint."""
    return mujoco.MjModel.from_xml_string(model_xml(robot))


@lru_cache(maxsize=1)
def _passive_function() -> ca.Function:
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    c1, s1, c2, s2 = ca.cos(q[0]), ca.sin(q[0]), ca.cos(q[1]), ca.sin(q[1])
    # Rx(θ1) Ry(φ1) ẑ = b and Ry(θ2) Rx(φ2) ẑ = b with b ∝ (C1 S2, −S1 C2, C1 C2)
    phi = ca.vertcat(ca.atan2(c1 * s2, c2), ca.atan2(s1 * c2, c1))
    phid = ca.jtimes(phi, q, qd)
    phidd = ca.jtimes(phid, q, qd) + ca.jtimes(phi, q, qdd)
    return ca.Function("passive", [q, qd, qdd], [phi, phid, phidd])


def _passive_all(
    q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q, qd, qdd = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, qd, qdd))
    function = _passive_function().map(q.shape[0])
    phi, phid, phidd = function(q.T, qd.T, qdd.T)
    return np.asarray(phi).T, np.asarray(phid).T, np.asarray(phidd).T


def passive_angles(q: np.ndarray) -> np.ndarray:
    """Passive hinge angles (φ1, φ2), shape (N, 2), rad, for joint angles q (N, 2), rad.

    φ1 = atan2(C1 S2, C2) turns the upper platform on its rail about N_u, φ2 =
    atan2(S1 C2, C1) the lower platform about N_L, so both z axes point along B.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    zeros = np.zeros_like(q)
    return _passive_all(q, zeros, zeros)[0]


def passive_motion(
    q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Passive angles, rates and accelerations, each (N, 2), from the loop closure."""
    return _passive_all(q, qd, qdd)


class _Indices:
    def __init__(self, model: mujoco.MjModel) -> None:
        def address(names: tuple[str, ...], kind: str) -> np.ndarray:
            return np.array([getattr(model.joint(n), kind)[0] for n in names])

        self.qpos_active = address(ACTIVE_JOINTS, "qposadr")
        self.qpos_passive = address(PASSIVE_JOINTS, "qposadr")
        self.dof_active = address(ACTIVE_JOINTS, "dofadr")
        self.dof_passive = address(PASSIVE_JOINTS, "dofadr")


def set_state(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    q: np.ndarray,
    qd: np.ndarray | None = None,
    qdd: np.ndarray | None = None,
) -> None:
    """Put one configuration (2,) with rates and accelerations into ``data`` (qpos, qvel,
    qacc of all four joints, the passive ones from the loop closure) and run ``mj_forward``.
    """
    index = _Indices(model)
    q = np.asarray(q, dtype=float).reshape(2)
    qd = np.zeros(2) if qd is None else np.asarray(qd, dtype=float).reshape(2)
    qdd = np.zeros(2) if qdd is None else np.asarray(qdd, dtype=float).reshape(2)
    phi, phid, phidd = (a[0] for a in _passive_all(q, qd, qdd))
    data.qpos[index.qpos_active], data.qpos[index.qpos_passive] = q, phi
    data.qvel[index.dof_active], data.qvel[index.dof_passive] = qd, phid
    data.qacc[index.dof_active], data.qacc[index.dof_passive] = qdd, phidd
    data.qfrc_applied[:] = 0.0
    data.ctrl[:] = 0.0
    mujoco.mj_forward(model, data)
    # mj_forward overwrote qacc with its own forward dynamics; put the kinematic one back
    data.qacc[index.dof_active], data.qacc[index.dof_passive] = qdd, phidd


def equality_jacobian(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """Rows of ``efc_J`` that belong to equality constraints, shape (n_eq_rows, nv)."""
    rows = np.flatnonzero(data.efc_type[: data.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    if mujoco.mj_isSparse(model):
        dense = np.zeros((data.nefc, model.nv))
        mujoco.mju_sparse2dense(
            dense, data.efc_J, data.efc_J_rownnz, data.efc_J_rowadr, data.efc_J_colind
        )
    else:
        dense = np.asarray(data.efc_J[: data.nefc * model.nv]).reshape(data.nefc, model.nv)
    return dense[rows]


def rail_friction(model: mujoco.MjModel, data: mujoco.MjData, robot: Robot) -> np.ndarray:
    """Generalised forces (nv,) of the rails' Coulomb friction for the state in ``data``,
    from MuJoCo's own quantities: each platform's sliding velocity on its rail at its
    point on the radial axis (B for the upper platform, D for the lower: r_u and r_L along
    the platform's z axis), (ω_platform − ω_arc) × point from the bodies' angular
    velocities (every joint axis passes through the isocenter); the normal force the
    platform's weight (MuJoCo's body mass, the payload's included, and gravity) along the
    radial contact normal; the force μ N against the sliding, applied at that point."""
    qfrc = np.zeros(model.nv)
    weight = -float(model.opt.gravity[2])
    for platform, arc, radius in (
        ("upper_platform", "upper_arc", robot.upper_platform_radius),
        ("lower_platform", "lower_arc", robot.lower_platform_radius),
    ):
        body, rail = model.body(platform).id, model.body(arc).id
        radial = data.xmat[body].reshape(3, 3)[:, 2]
        point = data.xpos[body] + radius * radial
        sliding = np.cross(
            _angular_velocity(model, data, body) - _angular_velocity(model, data, rail), point
        )
        speed = float(np.linalg.norm(sliding))
        if speed == 0.0:
            continue
        normal = model.body_mass[body] * weight * radial[2]
        force = -robot.friction.mu * normal * sliding / speed
        mujoco.mj_applyFT(model, data, force, np.zeros(3), point, body, qfrc)
    return qfrc


def _angular_velocity(model: mujoco.MjModel, data: mujoco.MjData, body: int) -> np.ndarray:
    """A body's angular velocity in the world frame, rad/s."""
    velocity = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
    return velocity[:3]


def _inverse_one(
    model: mujoco.MjModel, data: mujoco.MjData, index: _Indices, applied: np.ndarray
) -> tuple[np.ndarray, float]:
    """τ (2,) and the relative residual of M q̈ + bias = S τ + J_cᵀ λ + ``applied`` for the
    state in data."""
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    lhs = mass @ data.qacc + data.qfrc_bias - applied
    jacobian = equality_jacobian(model, data)
    select = np.zeros((model.nv, 2))
    select[index.dof_active, [0, 1]] = 1.0
    system = np.hstack([select, jacobian.T])
    solution, *_ = np.linalg.lstsq(system, lhs, rcond=None)
    residual = np.linalg.norm(system @ solution - lhs) / max(np.linalg.norm(lhs), 1e-300)
    return solution[:2], float(residual)


def multibody_inverse_dynamics(
    robot: Robot,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    model: mujoco.MjModel | None = None,
    return_residual: bool = False,
    friction: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Actuator torques (N, 2), N·m, from MuJoCo's own mass matrix, bias forces and
    loop-closure Jacobian, with the rails' friction (:func:`rail_friction`) if asked.

    For every sample the full state (active and passive joints, passive rates and
    accelerations from differentiating the loop closure exactly) goes into MuJoCo; then
    M q̈ + bias = S τ + J_cᵀ λ, with M from ``mj_fullM``, bias = ``qfrc_bias`` and J_c the
    equality rows of ``efc_J``, is solved for τ (the actuated joints, S selects them) and
    λ by least squares: J_c has a redundant row (see the module docstring) so λ is not
    unique, τ is. With ``friction`` the rails' friction forces join the right-hand side.

    With ``return_residual`` also the relative residual of that solve per sample (N,): it
    is zero to rounding when the passive accelerations satisfy the loop closure.
    """
    model = build_model(robot) if model is None else model
    data = mujoco.MjData(model)
    index = _Indices(model)
    q, qd, qdd = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, qd, qdd))
    torque = np.empty((q.shape[0], 2))
    residual = np.empty(q.shape[0])
    for k in range(q.shape[0]):
        set_state(model, data, q[k], qd[k], qdd[k])
        applied = rail_friction(model, data, robot) if friction else np.zeros(model.nv)
        torque[k], residual[k] = _inverse_one(model, data, index, applied)
    return (torque, residual) if return_residual else torque


def energy(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[float, float]:
    """MuJoCo's own (potential, kinetic) energy, J, of the state in ``data``."""
    mujoco.mj_energyPos(model, data)
    mujoco.mj_energyVel(model, data)
    return float(data.energy[0]), float(data.energy[1])


def simulate_open_loop(
    robot: Robot,
    q0: np.ndarray,
    qd0: np.ndarray,
    torque_of_time: Callable[[float], np.ndarray],
    duration: float,
    dt: float = 1e-4,
    model: mujoco.MjModel | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Forward-simulate the robot under given actuator torques: times (M,), s, and joint
    angles (M, 2), rad, of both actuators, starting at (q0, qd0) with the passive joints
    placed on the loop closure.

    ``torque_of_time(t)`` returns the two torques, N·m, at time t (from 0). MuJoCo holds
    applied forces constant through a step, so each step takes the torque at its midpoint
    (second-order accurate in dt). RK4 with the stiff, nearly hard loop closure of
    ``EQUALITY_SOLREF`` / ``EQUALITY_SOLIMP``; the time constant is kept above 2·dt, as
    MuJoCo requires. A given ``model`` is copied, not changed.
    """
    model = build_model(robot) if model is None else copy.deepcopy(model)
    model.opt.timestep = dt
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    model.eq_solref[:, 0] = max(EQUALITY_SOLREF[0], 2.0 * dt)
    data = mujoco.MjData(model)
    index = _Indices(model)
    set_state(model, data, q0, qd0)
    steps = int(round(duration / dt))
    t = np.arange(steps + 1) * dt
    q = np.empty((steps + 1, 2))
    q[0] = data.qpos[index.qpos_active]
    for k in range(steps):
        data.qfrc_applied[:] = 0.0
        data.qfrc_applied[index.dof_active] = np.asarray(
            torque_of_time(t[k] + 0.5 * dt), dtype=float
        ).reshape(2)
        mujoco.mj_step(model, data)
        q[k + 1] = data.qpos[index.qpos_active]
    return t, q


def open_loop_deviation(
    robot: Robot,
    trajectory: Trajectory,
    start_s: float = 1.0,
    duration_s: float = 1.0,
    torque_scale: float = 1.0,
    dt: float = 1e-4,
) -> float:
    """Largest joint-angle deviation, rad, of an open-loop MuJoCo run from the plan.

    MuJoCo's own inverse-dynamics torques along the plan (sampled every millisecond from
    ``start_s`` and interpolated by a cubic spline, times ``torque_scale``) are applied from
    the planned state at ``start_s`` for ``duration_s``. The robot is unstable under
    gravity, so a small deviation says the torques are right.
    """
    from scipy.interpolate import CubicSpline

    t = start_s + np.linspace(0.0, duration_s, int(round(duration_s * 1000)) + 1)
    q, qd, qdd = trajectory.position(t), trajectory.velocity(t), trajectory.acceleration(t)
    model = build_model(robot)
    torque = torque_scale * multibody_inverse_dynamics(robot, q, qd, qdd, model=model)
    times, simulated = simulate_open_loop(
        robot, q[0], qd[0], CubicSpline(t - start_s, torque), duration_s, dt=dt, model=model
    )
    return float(np.max(np.abs(simulated - trajectory.position(start_s + times))))
