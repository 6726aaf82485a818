"""The simulated robot: the one model's dynamics under two Dynamixel position controllers.

The plant integrates the Lagrange model of :mod:`spm_opt.model.dynamics`,
τ = M(q) q̈ + bias(q, q̇) + C(q) σ with σ ∈ sign(A(q) q̇), where A q̇ are the rates at
which the platforms slide on their rails and C = Aᵀ diag(F) holds their Coulomb friction
(Eqs. 20–22, exact sign). Sticking is handled exactly: each step is the implicit
(Moreau) time step, the unique minimiser of a convex function of the new joint rates, so a
platform whose drive cannot overcome its friction stays at rest instead of chattering.

The plant robot may carry what a planning model leaves out: the actuators' reflected rotor
inertia (added to M's diagonal), viscous and Coulomb friction in the joints' gear trains
(Coulomb as two more lines of the same implicit step), gear losses (the load gets η τ from
a motor that drives it in the step, τ / η from one it is driven back by: the step is solved
again with the other side where its power disagrees with the side it was solved with) and
encoder zero offsets (the encoders read θ + offset, and each position loop holds its reading).

Each actuator runs the Dynamixel PRO's integrated position controller as the reference
describes it (the paper's Fig. 18): a P position loop gives a rate command, limited by
the Velocity Limit; a PI velocity loop turns it into a current command, limited by the
Torque Limit (a current limit); the actuator's current map gives the torque. The
firmware's scaling of its gain units to physical units is not published: the factors in
:class:`PlantSettings` are assumptions, chosen for this robot's inertia (about
0.005 kg·m² per joint): with the default gains (position P 32, velocity P 256, velocity
I 16) the position loop has a 32 1/s bandwidth (a 5 mrad lag at 0.17 rad/s) and the
velocity loop about 30 Hz. :class:`PlantSettings` also holds the gains the actuators
power on with (the defaults, or others for a plant with other loops);
:func:`loop_rates` gives a plant's loops in the robot file's terms (Kp and ωv, 1/s) and
:func:`gains_for_rates` the gains for wanted ones. The anti-windup of the firmware (a gain
the user cannot set) is modelled as conditional integration: the integrator holds while the
current saturates.
The velocity loop's proportional and integral terms are integrated implicitly, so the
step is stable at any gain.

An actuator whose torque is off is held by its 502:1 gear train (which the load cannot
back-drive): its joint stays where it is. Sensors: Present Position quantised to the
encoder's 361,384 pulse/rev, Present Velocity to its 0.00199234 rpm unit, Present Current
to its 16.11 mA unit after seeded Gaussian noise.

What the sensors cannot show, :class:`TrueState` and :class:`StateTrace` give tests and
post-mortems: the plant's exact joint angles and rates, without quantisation or noise.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from spm_opt.model import dynamics, geometry
from spm_opt.model.params import Robot

DEFAULT_POSITION_P_GAIN = 32
DEFAULT_VELOCITY_P_GAIN = 256
DEFAULT_VELOCITY_I_GAIN = 16
"""The control table's default gains (addresses 594, 588, 586)."""

SIDE_TRIALS = 3
"""Solves of a step at most, each with the gear train's side (driving or driven) the last
one's power took, until they agree (a torque that would sit at zero may alternate: the
last is kept)."""

OVERLOAD_BIT = 5
"""Hardware Error Status bit of an overload."""

Pair = tuple[float, float]
Matrix = tuple[Pair, Pair]


@dataclass(frozen=True)
class PlantSettings:
    """Assumptions of the simulated plant (SI unless the name says otherwise).

    Attributes
    ----------
    step_s : float, s
        Internal integration step (1 ms: a 1 kHz plant).
    position_gain_per_unit : float, 1/s per unit of Position P Gain
    velocity_p_gain_per_unit : float, N·m/(rad/s) per unit of Velocity P Gain
    velocity_i_gain_per_unit : float, N·m/rad per unit of Velocity I Gain
    position_p_gain, velocity_p_gain, velocity_i_gain : (int, int), control-table units
        The actuators' gains (θ1, θ2) at power-on (the control table's defaults unless a test
        builds a plant with other loops: :func:`gains_for_rates`).
    current_noise_a : float, A
        Standard deviation of the noise on Present Current (before quantisation).
    moving_threshold_rad_s : float, rad/s
        Speed above which the actuator reports Moving.
    seed : int
        Seed of the current noise.
    """

    step_s: float = 1e-3
    position_gain_per_unit: float = 1.0
    velocity_p_gain_per_unit: float = 3.7e-3
    velocity_i_gain_per_unit: float = 2.5
    position_p_gain: tuple[int, int] = (DEFAULT_POSITION_P_GAIN, DEFAULT_POSITION_P_GAIN)
    velocity_p_gain: tuple[int, int] = (DEFAULT_VELOCITY_P_GAIN, DEFAULT_VELOCITY_P_GAIN)
    velocity_i_gain: tuple[int, int] = (DEFAULT_VELOCITY_I_GAIN, DEFAULT_VELOCITY_I_GAIN)
    current_noise_a: float = 0.008
    moving_threshold_rad_s: float = 0.01
    seed: int = 0


def loop_rates(robot: Robot, settings: PlantSettings) -> tuple[np.ndarray, np.ndarray]:
    """A plant's loops in the robot file's terms, per joint (2,), 1/s: Kp, the Position P
    Gain's; ωv, the Velocity P Gain's N·m·s/rad over the joint's inertia at θ = 0 (M's
    diagonal of ``robot``, reflected rotor inertia included)."""
    gain = settings.position_gain_per_unit * np.array(settings.position_p_gain, dtype=float)
    damping = settings.velocity_p_gain_per_unit * np.array(settings.velocity_p_gain, dtype=float)
    return gain, damping / _joint_inertia(robot)


def gains_for_rates(
    robot: Robot, settings: PlantSettings, gain_per_s: Pair, bandwidth_per_s: Pair
) -> tuple[tuple[int, int], tuple[int, int]]:
    """The Position P Gains and Velocity P Gains (control-table units, rounded; per joint)
    that give a plant of ``robot`` the loops Kp ``gain_per_s`` and ωv ``bandwidth_per_s``
    (1/s per joint; the inverse of :func:`loop_rates`); ``settings`` gives the units."""
    inertia = _joint_inertia(robot)
    position = [round(kp / settings.position_gain_per_unit) for kp in gain_per_s]
    velocity = [
        round(wv * m / settings.velocity_p_gain_per_unit)
        for wv, m in zip(bandwidth_per_s, inertia, strict=True)
    ]
    return (position[0], position[1]), (velocity[0], velocity[1])


def closed_loop_settings(robot: Robot) -> PlantSettings:
    """The simulated plant's settings whose loops are ``robot``'s file's (Kp, ωv)."""
    base = PlantSettings()
    actuator = robot.actuator
    position, velocity = gains_for_rates(
        robot, base, actuator.position_loop_gain_per_s, actuator.velocity_loop_bandwidth_per_s
    )
    return replace(base, position_p_gain=position, velocity_p_gain=velocity)


def _joint_inertia(robot: Robot) -> np.ndarray:
    """Each joint's inertia at θ = 0 (2,), kg·m²: M's diagonal plus the rotor's."""
    mass = dynamics.mass_matrix(robot, np.zeros(2))[0]
    return np.diag(mass) + robot.actuator.rotor_inertia_kg_m2


@dataclass(frozen=True)
class TrueState:
    """The plant's exact state at one instant (no encoder quantisation, no noise).

    Attributes
    ----------
    time_s : float, s
        On the clock of whoever sampled it (the backend's clock, or the emulator's).
    position_rad : ndarray, shape (2,), rad
    velocity_rad_s : ndarray, shape (2,), rad/s
    goal_rad : ndarray, shape (2,), rad
        The goal positions the actuators hold.
    """

    time_s: float
    position_rad: np.ndarray
    velocity_rad_s: np.ndarray
    goal_rad: np.ndarray


class StateTrace:
    """The plant's true state, sampled over a run: appended in memory, saved as ``.npz``.
    Between two samples the plant takes steps the samples do not show: each sample also
    holds the largest speed of each actuator over the steps since the sample before
    (``peak_speed_rad_s``), where the loops' answer to the goals' steps peaks."""

    FIELDS = (
        "time_s",
        "position_rad",
        "velocity_rad_s",
        "goal_rad",
        "current_a",
        "peak_speed_rad_s",
    )

    def __init__(self) -> None:
        self._rows: list[tuple[float, ...]] = []

    def __len__(self) -> int:
        return len(self._rows)

    def record(self, time_s: float, plant: DynamixelPlant) -> None:
        """Append the plant's present state, sampled at ``time_s`` (s): its position and
        rate in the model's joint coordinates of its tool's true direction (its joint
        angles themselves when its mechanism is ideal; :mod:`spm_opt.model.geometry`)."""
        q, v, goal = plant.position_rad, plant.velocity_rad_s, plant.goal_position_rad
        mechanism = plant.robot.mechanism
        if not mechanism.is_ideal:
            q, v = (
                geometry.model_joint_angles(q[None, :], mechanism)[0],
                geometry.model_joint_rates(q[None, :], v[None, :], mechanism)[0],
            )
        current, peak = plant.current_a, plant.take_peak_speed()
        self._rows.append(
            (time_s, q[0], q[1], v[0], v[1], goal[0], goal[1], current[0], current[1], *peak)
        )

    def arrays(self, origin_s: float = 0.0) -> dict[str, np.ndarray]:
        """``time_s`` (n,) and ``position_rad``, ``velocity_rad_s``, ``goal_rad`` and
        ``current_a`` (the motor currents, before the sensor's noise and rounding) and
        ``peak_speed_rad_s`` (the actuators' own, rad/s) (n, 2). ``origin_s`` (s) is
        subtracted from the times: an execution log's ``clock_origin_s`` puts them on the
        log's clock."""
        table = np.array(self._rows, dtype=float).reshape(-1, 11)
        return {
            "time_s": table[:, 0] - origin_s,
            "position_rad": table[:, 1:3],
            "velocity_rad_s": table[:, 3:5],
            "goal_rad": table[:, 5:7],
            "current_a": table[:, 7:9],
            "peak_speed_rad_s": table[:, 9:11],
        }

    def save(self, path: str | Path) -> None:
        """Write :meth:`arrays` to ``path`` (``.npz``)."""
        with open(path, "wb") as file:
            np.savez(file, **self.arrays())

    @staticmethod
    def load(path: str | Path, origin_s: float = 0.0) -> dict[str, np.ndarray]:
        """The arrays a :meth:`save` wrote, their times less ``origin_s`` (s; see
        :meth:`arrays`)."""
        with np.load(path) as data:
            arrays = {name: data[name] for name in StateTrace.FIELDS}
        arrays["time_s"] = arrays["time_s"] - origin_s
        return arrays


class DynamixelPlant:
    """Two actuators and the robot, integrated in steps of ``settings.step_s``.

    Per-joint arrays (index 0: θ1, index 1: θ2) mirror the control-table items they model
    and may be written element by element: ``goal_position_rad``, ``velocity_limit_rad_s``,
    ``current_limit_a``, the gains (control-table units), ``encoder_stuck``.
    """

    def __init__(
        self,
        robot: Robot,
        settings: PlantSettings | None = None,
        start_rad: np.ndarray | None = None,
    ) -> None:
        self.robot = robot
        self.settings = settings or PlantSettings()
        actuator = robot.actuator
        self._actuator = actuator
        self._terms = dynamics.PlantTerms(robot)
        self._rotor = actuator.rotor_inertia_kg_m2
        self._damping = tuple(actuator.viscous_friction_nm_s_rad)
        self._joint_friction = [float(f) for f in actuator.coulomb_friction_nm]
        self._efficiency = actuator.gear_efficiency
        self._offset = [float(v) for v in robot.encoder_offset]
        self._driving = [True, True]  # whether each motor drove its load in the last step
        self._rng = np.random.default_rng(self.settings.seed)
        start = np.zeros(2) if start_rad is None else np.asarray(start_rad, dtype=float)
        self.time_s = 0.0
        self.position_rad = start.copy()
        self.velocity_rad_s = np.zeros(2)
        self.current_a = np.zeros(2)
        self._integral = np.zeros(2)
        self._peak_speed = [0.0, 0.0]
        self.goal_position_rad = start + robot.encoder_offset  # in the encoders' reading
        self.torque_enabled = np.zeros(2, dtype=bool)
        self.velocity_limit_rad_s = np.full(2, actuator.velocity_limit_rad_s)
        self.current_limit_a = np.full(2, actuator.continuous_current_a * 1.5)
        self.position_p_gain = np.array(self.settings.position_p_gain, dtype=np.int64)
        self.velocity_p_gain = np.array(self.settings.velocity_p_gain, dtype=np.int64)
        self.velocity_i_gain = np.array(self.settings.velocity_i_gain, dtype=np.int64)
        self.hardware_error = np.zeros(2, dtype=np.int64)
        self.encoder_stuck = np.zeros(2, dtype=bool)
        self._reported_pulses = actuator.pulses(start + robot.encoder_offset)

    def true_state(self, time_s: float) -> TrueState:
        """The exact present state (copies), labelled with ``time_s`` (s)."""
        return TrueState(
            time_s,
            self.position_rad.copy(),
            self.velocity_rad_s.copy(),
            self.goal_position_rad.copy(),
        )

    # ----------------------------------------------------------------- commands
    def enable_torque(self, joint: int, on: bool) -> None:
        """Torque Enable: switching on holds the present position (goal := what the
        encoder reads)."""
        if on and not self.torque_enabled[joint]:
            self.goal_position_rad[joint] = self.position_rad[joint] + self._offset[joint]
            self._integral[joint] = 0.0
        self.torque_enabled[joint] = bool(on) and self.hardware_error[joint] == 0

    def trigger_hardware_error(self, joint: int, bit: int) -> None:
        """Set a Hardware Error Status bit; as the firmware does, torque goes off."""
        self.hardware_error[joint] |= 1 << bit
        self.torque_enabled[joint] = False

    def reboot(self, joint: int) -> None:
        """Clear the hardware error; torque is off after a reboot."""
        self.hardware_error[joint] = 0
        self.torque_enabled[joint] = False

    # ------------------------------------------------------------------ sensors
    def present_position_pulses(self) -> np.ndarray:
        """Present Position, pulses (signed), of θ + the encoder offset; frozen where the
        encoder is stuck."""
        live = self._actuator.pulses(self.position_rad + self.robot.encoder_offset)
        self._reported_pulses = np.where(self.encoder_stuck, self._reported_pulses, live)
        return self._reported_pulses.copy()

    def present_velocity_units(self) -> np.ndarray:
        """Present Velocity in units of 0.00199234 rpm (signed)."""
        return self._actuator.velocity_units(self.velocity_rad_s)

    def present_current_units(self) -> np.ndarray:
        """Present Current in units of 16.11 mA (signed), with the seeded noise."""
        noise = self._rng.normal(0.0, self.settings.current_noise_a, 2)
        return self._actuator.current_units(self.current_a + noise)

    def take_peak_speed(self) -> tuple[float, float]:
        """Each actuator's largest speed (rad/s) over the steps since this was last taken,
        the present one's included; taking it starts the next span."""
        peak = (self._peak_speed[0], self._peak_speed[1])
        self._peak_speed = [abs(float(v)) for v in self.velocity_rad_s]
        return peak

    def moving(self) -> np.ndarray:
        """Moving flags: joints turning faster than the threshold."""
        return np.abs(self.velocity_rad_s) > self.settings.moving_threshold_rad_s

    # -------------------------------------------------------------- integration
    def advance_to(self, time_s: float) -> None:
        """Integrate in whole internal steps up to ``time_s`` (no-op if not later). A time
        within a millionth of a step of a step's end counts as on it: the loop's deadlines,
        sums of periods, drift by picoseconds, and a read on a boundary would otherwise see
        the state one step early at some deadlines and not at others."""
        steps = int(np.floor((time_s - self.time_s) / self.settings.step_s + 1e-6))
        for _ in range(max(steps, 0)):
            self._step()

    def _step(self) -> None:
        # plain floats: on two joints, numpy's per-call overhead would cost ten times more
        s, dt = self.settings, self.settings.step_s
        mass, bias, slide_map, friction = self._terms(self.position_rad, self.velocity_rad_s)
        (m00, m01), (m10, m11) = mass.tolist()
        m00, m11 = m00 + self._rotor, m11 + self._rotor
        (a00, a01), (a10, a11) = slide_map.tolist()
        (c00, c01), (c10, c11) = friction.tolist()
        det = a00 * a11 - a01 * a10
        # C = Aᵀ diag(F): the friction torque of each slide, times Δt; then the joints'
        lines = [(a00, a01), (a10, a11)]
        thresholds = [dt * (a11 * c00 - a10 * c10) / det, dt * (a00 * c11 - a01 * c01) / det]
        if any(self._joint_friction):
            lines += [(1.0, 0.0), (0.0, 1.0)]
            thresholds += [dt * f for f in self._joint_friction]
        enabled = [bool(e) for e in self.torque_enabled]
        q, v = self.position_rad.tolist(), self.velocity_rad_s.tolist()
        bias_torque = bias.tolist()
        command, gain, held = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
        for j in range(2):
            if enabled[j]:
                limit = float(self.velocity_limit_rad_s[j])
                kp = s.position_gain_per_unit * float(self.position_p_gain[j])
                ki = s.velocity_i_gain_per_unit * float(self.velocity_i_gain[j])
                seen = q[j] + self._offset[j]  # the actuator's own encoder
                command[j] = min(max(kp * (float(self.goal_position_rad[j]) - seen), -limit), limit)
                # τ = K (v_cmd − v⁺) + Ki z, the integral taken at the end of the step
                gain[j] = s.velocity_p_gain_per_unit * float(self.velocity_p_gain[j]) + ki * dt
                held[j] = ki * float(self._integral[j])
        # the load gets η τ from a motor that drives it, τ / η from one it drives back: the
        # side the step's own power takes (from the last step's, changed while they differ)
        driving = list(self._driving)
        for _ in range(SIDE_TRIALS):
            share = [self._efficiency if d else 1.0 / self._efficiency for d in driving]
            problem = _StepProblem(
                ((m00, m01), (m10, m11)),
                lines,
                thresholds,
                dt,
                self._damping,
                (share[0], share[1]),
            )
            new_rate, torque, current, saturated = self._solve(
                problem, v, bias_torque, list(gain), command, list(held), enabled
            )
            taken = [torque[j] * new_rate[j] >= 0.0 for j in range(2)]
            if taken == driving or self._efficiency == 1.0:
                break
            driving = taken
        for j in range(2):
            integrating = enabled[j] and not saturated[j]
            if integrating:
                self._integral[j] += dt * (command[j] - new_rate[j])
            elif not enabled[j]:
                self._integral[j] = 0.0
            self.current_a[j] = current[j] if enabled[j] else 0.0
            self.position_rad[j] = q[j] + dt * new_rate[j]
            self.velocity_rad_s[j] = new_rate[j]
            self._peak_speed[j] = max(self._peak_speed[j], abs(new_rate[j]))
            self._driving[j] = torque[j] * new_rate[j] >= 0.0
        self.time_s += dt

    def _solve(
        self,
        problem: _StepProblem,
        rate: list[float],
        bias: list[float],
        gain: list[float],
        command: list[float],
        held: list[float],
        enabled: list[bool],
    ) -> tuple[list[float], list[float], list[float], list[bool]]:
        """One implicit step: new rates, motor torques and currents, and which currents the
        Torque Limit holds (there the torque is the limit's: ``gain`` and ``held``, which
        this changes, then give it)."""
        new_rate, torque = problem.solve(rate, bias, gain, command, held, enabled)
        current = [self._current(t) for t in torque]
        saturated = [
            enabled[j] and abs(current[j]) > float(self.current_limit_a[j]) for j in range(2)
        ]
        if any(saturated):
            for j in range(2):
                if saturated[j]:
                    limit = float(self.current_limit_a[j])
                    current[j] = min(max(current[j], -limit), limit)
                    held[j] = float(self._actuator.current_map.torque(current[j]))
                    gain[j] = 0.0
            new_rate, torque = problem.solve(rate, bias, gain, command, held, enabled)
            current = [self._current(t) for t in torque]
        return new_rate, torque, current, saturated

    def _current(self, torque_nm: float) -> float:
        """Motor current, A, for an output torque (the actuator's map, on one float)."""
        table = self._actuator.current_map
        magnitude = abs(torque_nm)
        torques, currents = table.torques_nm, table.currents_a
        k = min(max(bisect.bisect_right(torques, magnitude) - 1, 0), len(torques) - 2)
        slope = (currents[k + 1] - currents[k]) / (torques[k + 1] - torques[k])
        return math.copysign(currents[k] + slope * (magnitude - torques[k]), torque_nm)


class _StepProblem:
    """One implicit step: new rates v⁺ and motor torques τ = gain (v_cmd − v⁺) + held, of
    which the load gets s τ (``share``: the gear train's efficiency or its inverse).

    v⁺ minimises ½ v⁺ᵀ W v⁺ − bᵀ v⁺ + Σ_k c_k |a_k · v⁺| with
    W = M + Δt diag(s gain + f_v), b = M v + Δt (s (gain v_cmd + held) − bias),
    c_k = Δt F_k: the implicit (Moreau) step with the joints' viscous friction f_v
    (``damping``) and Coulomb friction on the ``lines`` a_k (the slides, rows of A, then
    the joints themselves when their gear trains have Coulomb friction). Joints with torque
    off are held by their gear train (v⁺ = 0 there).
    """

    def __init__(
        self,
        mass: Matrix,
        lines: list[Pair],
        thresholds: list[float],
        dt: float,
        damping: Pair,
        share: Pair,
    ) -> None:
        self.mass, self.lines, self.thresholds, self.dt = mass, lines, thresholds, dt
        self.damping, self.share = damping, share

    def solve(
        self,
        rate: list[float],
        bias: list[float],
        gain: list[float],
        command: list[float],
        held: list[float],
        enabled: list[bool],
    ) -> tuple[list[float], list[float]]:
        (m00, m01), (m10, m11) = self.mass
        dt, (f0, f1), (s0, s1) = self.dt, self.damping, self.share
        weights = ((m00 + dt * (s0 * gain[0] + f0), m01), (m10, m11 + dt * (s1 * gain[1] + f1)))
        linear = (
            m00 * rate[0] + m01 * rate[1] + dt * (s0 * (gain[0] * command[0] + held[0]) - bias[0]),
            m10 * rate[0] + m11 * rate[1] + dt * (s1 * (gain[1] * command[1] + held[1]) - bias[1]),
        )
        new = _minimise(weights, linear, self.lines, self.thresholds, enabled)
        torque = [
            gain[j] * (command[j] - new[j]) + held[j] if enabled[j] else 0.0 for j in range(2)
        ]
        return list(new), torque


def _minimise(
    weights: Matrix,
    linear: Pair,
    lines: Sequence[Pair],
    thresholds: Sequence[float],
    free: list[bool],
) -> Pair:
    """argmin over v of ½ vᵀWv − bᵀv + Σ_k c_k |a_k·v| (a_k: ``lines``), with v_j = 0 where
    not free.

    Every line a_k·v = 0 passes through the origin, so the minimiser of this convex
    function is the smooth stationary point of one sign pattern (each term sliding), the
    minimum along one line (that term stuck), or the origin: every candidate is computed in
    closed form and the one of least value is the minimiser. A stationary point that slides
    the way its sign pattern says is the minimiser at once: the rest are valued only when
    something sticks (measured on a plant with joint Coulomb friction: 0.14 ms a call before,
    0.044 after, the same states to the bit).
    """
    (w00, w01), (w10, w11) = weights
    b0, b1 = linear
    terms = list(zip(lines, thresholds, strict=True))

    def friction(v0: float, v1: float) -> float:
        return sum(c * abs(a0 * v0 + a1 * v1) for (a0, a1), c in terms)

    def value(v0: float, v1: float) -> float:
        quadratic = 0.5 * (v0 * (w00 * v0 + w01 * v1) + v1 * (w10 * v0 + w11 * v1))
        return quadratic - b0 * v0 - b1 * v1 + friction(v0, v1)

    def along(d0: float, d1: float) -> Pair:
        # 1-D soft threshold: min over α of ½ w α² − β α + c |α|
        w = d0 * (w00 * d0 + w01 * d1) + d1 * (w10 * d0 + w11 * d1)
        beta = b0 * d0 + b1 * d1
        alpha = math.copysign(max(abs(beta) - friction(d0, d1), 0.0), beta) / w
        return alpha * d0, alpha * d1

    if not (free[0] or free[1]):
        return 0.0, 0.0
    if not (free[0] and free[1]):
        return along(1.0, 0.0) if free[0] else along(0.0, 1.0)
    det = w00 * w11 - w01 * w10
    candidates = [(0.0, 0.0)]
    for signs in itertools.product((1.0, -1.0), repeat=len(terms)):
        # W v = b − Aᵀ (c ∘ s)
        r0, r1 = b0, b1
        for ((a0, a1), c), sign in zip(terms, signs, strict=True):
            r0 -= a0 * c * sign
            r1 -= a1 * c * sign
        v = ((w11 * r0 - w01 * r1) / det, (w00 * r1 - w10 * r0) / det)
        # every term sliding the way its sign says: the function is smooth there and
        # stationary, so (strictly convex) this is the minimiser and no other need be valued
        sliding = zip(terms, signs, strict=True)
        if all((a0 * v[0] + a1 * v[1]) * sign > 0.0 for ((a0, a1), _), sign in sliding):
            return v
        candidates.append(v)
    for (k0, k1), _ in terms:
        norm = math.hypot(k0, k1)
        candidates.append(along(-k1 / norm, k0 / norm))
    return min(candidates, key=lambda v: value(*v))
