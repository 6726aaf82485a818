"""An identification checked: the torque predictions of a robot on logs, and a known plant's
true base parameters.

The prediction error is measured as the fit sees the torques: both the measured torques
and the model's through the samples' parallel filter (:mod:`spm_opt.identify.samples`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.identify.samples import Samples
from spm_opt.model import dynamics
from spm_opt.model.base_parameters import SAMPLES, base_parameters, random_states
from spm_opt.model.params import Robot
from spm_opt.model.regressor import regressor

TRUTH_RESIDUAL = 1e-9
"""Largest residual, relative to the largest torque, of a plant's torques in a prior's base
parameters (:func:`true_base_parameters`): above it the two robots differ in structure."""


def filtered_prediction(robot: Robot, samples: Samples) -> np.ndarray:
    """The model's actuator torques of ``robot`` at the samples' motion, through the
    parallel filter (M, 2), N·m."""
    return samples.parallel(dynamics.actuator_torque(robot, samples.q, samples.qd, samples.qdd))


def prediction_rms(robot: Robot, samples: Samples) -> np.ndarray:
    """RMS of measured − predicted torque per joint (2,), N·m, both through the parallel
    filter (:func:`filtered_prediction`)."""
    error = samples.parallel(samples.torque) - filtered_prediction(robot, samples)
    return np.sqrt(np.mean(error**2, axis=0))


def true_base_parameters(prior: Robot, plant: Robot) -> np.ndarray:
    """β (r,) of ``plant`` in ``prior``'s base parameters: least squares of the prior's
    base columns against the plant's torques at the joints (its model torques with a
    lossless gear train, less the prior's payload torque, as
    :func:`~spm_opt.identify.estimate.identify` fits) over random states. The robots may
    differ in lengths, payload and gravity (measured: a mass centre's or a rail's radius,
    the payload's mass, gravity leave the torques linear in the prior's base parameters);
    an error if they leave a residual above round-off."""
    base = base_parameters(prior)
    q, qd, qdd = random_states(prior, SAMPLES, seed=1)
    y, payload = regressor(prior, q, qd, qdd)
    actuator = dataclasses.replace(plant.actuator, gear_efficiency=1.0)
    torque = dynamics.actuator_torque(dataclasses.replace(plant, actuator=actuator), q, qd, qdd)
    a, b = base.columns(y).reshape(-1, base.rank), (torque - payload).reshape(-1)
    beta, *_ = np.linalg.lstsq(a, b, rcond=None)
    residual = float(np.max(np.abs(a @ beta - b)))
    if residual > TRUTH_RESIDUAL * float(np.max(np.abs(b))):
        raise InputError(
            f"plant robot {plant.name}: its torques are not linear in the base parameters of "
            f"{prior.name} (residual {residual:.3g} N·m); the robots differ in structure"
        )
    return beta
