"""Identification judged on plants whose truth is known: each plant runs an excitation and a
validation plan on the simulated robot, the prior robot is fitted to the excitation's log,
and the fit is held against the plant.

For each plant (:class:`PlantIdentification`): every base parameter's estimate, standard
error and truth (the plant's in the prior's base parameters,
:func:`~spm_opt.identify.validate.true_base_parameters`), η's, the torque prediction error on
the validation log of the prior, the identified robot and the plant's own model (the noise
floor), and the actuators' loops estimated against the plant's own. :func:`coverage` is the
share of truths within two standard errors.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spm_opt.execution import ExecutionSettings, SimulatedRobot, execute
from spm_opt.execution.plant import PlantSettings, loop_rates
from spm_opt.identify.estimate import Identification, identify
from spm_opt.identify.loop import LoopEstimate, estimate_loops
from spm_opt.identify.samples import DEFAULT_SAMPLING, log_samples
from spm_opt.identify.validate import prediction_rms, true_base_parameters
from spm_opt.identify.velocity_replay import replay_bandwidth
from spm_opt.model.params import Robot
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

__all__ = ["NOISE_FLOOR_NM", "NOISE_ROOM", "PlantIdentification", "coverage", "identify_plant"]

NOISE_FLOOR_NM = 0.0043
"""What the noise leaves of a filtered torque prediction, N·m: ten Present Current reads
of 8 mA noise in 16.11 mA units a period at 100 Hz through the 2 Hz filter (measured on the
simulated robot equal to its model, ``problems/identification.toml``'s excitation)."""
NOISE_ROOM = 1.5
"""A prediction within this many times :data:`NOISE_FLOOR_NM` is within the noise."""


@dataclass(frozen=True)
class PlantIdentification:
    """One plant identified from its own excitation log.

    Attributes
    ----------
    identification : Identification
    truth : ndarray, shape (r,)
        The plant's base parameters in the prior's basis.
    efficiency : float
        The plant's η.
    prior_rms, identified_rms, plant_rms : ndarray, shape (2,), N·m
        Torque prediction error on the validation log: the prior's, the identified robot's
        and the plant's own model's (what the noise leaves).
    loops : LoopEstimate
    plant_loops : (ndarray, ndarray), each shape (2,), 1/s
        The plant's own Kp and ωv.
    """

    identification: Identification
    truth: np.ndarray
    efficiency: float
    prior_rms: np.ndarray
    identified_rms: np.ndarray
    plant_rms: np.ndarray
    loops: LoopEstimate
    plant_loops: tuple[np.ndarray, np.ndarray]

    def sigmas(self) -> np.ndarray:
        """Each base parameter's distance from its truth (r,), in its standard errors."""
        ident = self.identification
        return np.abs(ident.estimate - self.truth) / ident.standard_error

    def efficiency_sigmas(self) -> float:
        """η's distance from the plant's, in its standard errors."""
        ident = self.identification
        return abs(ident.efficiency - self.efficiency) / ident.efficiency_error

    def model_holds(self) -> bool:
        """Whether the plant's own model predicts its validation torques within the noise
        (:data:`NOISE_ROOM` times :data:`NOISE_FLOOR_NM`), as identification measures them
        (:func:`~spm_opt.identify.validate.prediction_rms`). Where a gear train loses
        (η < 1), the velocity loop's answer to each goal step swings the motor's torque
        through the loss's two sides within the period; the log's sides of the reads keep
        that apart (on a plant with η 0.75 and ωv 227 1/s, 30 s of excitation, the plant's
        own model predicted its log's torques to 0.0054 and 0.0055 N·m with them, 0.0100
        and 0.0077 from the mean torque alone)."""
        return bool(np.all(self.plant_rms <= NOISE_ROOM * NOISE_FLOOR_NM))

    def prediction_gain(self) -> np.ndarray:
        """How many times better than the prior the identified robot predicts the
        validation torques, per joint (2,)."""
        return self.prior_rms / self.identified_rms


def identify_plant(
    problem: Problem,
    plant_robot: Robot,
    plant_settings: PlantSettings,
    excitation: Trajectory,
    validation: Trajectory,
    folder: Path,
    settings: ExecutionSettings,
    replay: bool = True,
) -> PlantIdentification:
    """Run ``excitation`` and ``validation`` on the simulated robot whose plant is
    ``plant_robot`` with ``plant_settings`` (logs in ``folder``), identify ``problem.robot``
    from the excitation's log and judge the fit; with ``replay``, the velocity loops from
    the log replayed through the identified model, as ``spm-opt identify`` does (about 10 s
    of compute)."""
    logs = []
    for name, plan in (("excitation", excitation), ("validation", validation)):
        backend = SimulatedRobot(
            problem.robot,
            start_rad=plan.position(plan.start_time),
            settings=plant_settings,
            plant_robot=plant_robot,
        )
        log = Path(folder) / f"{name}.csv"
        result = execute(plan, backend, problem, log, settings)
        result.raise_if_signalled()
        if not result.completed:
            raise RuntimeError(f"{name} on the plant stopped: {result.reason}")
        logs.append(log)
    identification = identify(problem.robot, log_samples([logs[0]], *DEFAULT_SAMPLING))
    loops = estimate_loops([logs[0]], problem.robot)
    if replay:
        found = replay_bandwidth([logs[0]], loops.robot(identification.robot))
        loops = dataclasses.replace(loops, replay=found)
    checked = log_samples([logs[1]], *DEFAULT_SAMPLING)
    robots = (problem.robot, identification.robot, plant_robot)
    rms = [prediction_rms(robot, checked) for robot in robots]
    return PlantIdentification(
        identification=identification,
        truth=true_base_parameters(problem.robot, plant_robot),
        efficiency=plant_robot.actuator.gear_efficiency,
        prior_rms=rms[0],
        identified_rms=rms[1],
        plant_rms=rms[2],
        loops=loops,
        plant_loops=loop_rates(plant_robot, plant_settings),
    )


def coverage(results: list[PlantIdentification], identified_only: bool) -> tuple[int, int]:
    """(truths within two standard errors, parameters counted) over ``results``: every
    base parameter and η, or only those reported identified."""
    within = counted = 0
    for result in results:
        ident = result.identification
        chosen = ident.identified if identified_only else np.ones_like(ident.identified)
        within += int(np.sum((result.sigmas() <= 2.0) & chosen))
        counted += int(np.sum(chosen))
        if ident.efficiency_identified or not identified_only:
            within += int(result.efficiency_sigmas() <= 2.0)
            counted += 1
    return within, counted
