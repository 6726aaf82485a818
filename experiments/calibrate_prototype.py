"""Calibrate the prototype's arc masses to the paper's Table IV RMS torques.

The paper publishes no masses or inertias, only (Table IV) the RMS actuator torques over
its 40 s trajectory without friction: 0.11 N·m (actuator 1) and 0.10 N·m (actuator 2).
Two numbers fix two parameters: the masses of the two arcs, their inertias scaled with
them (the same geometry, a different section). Everything else stays at the estimates in
problems/robots/prototype.toml. Prints the calibrated values to write into that file.

    python experiments/calibrate_prototype.py
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

import spm_opt as so
from spm_opt.cli.run import run_script
from spm_opt.model.dynamics import inverse_dynamics

ROOT = Path(__file__).resolve().parents[1]
TARGET_RMS_NM = np.array([0.11, 0.10])  # Table IV, friction off


def rms_torques(robot: so.Robot, trajectory: so.Trajectory) -> np.ndarray:
    t = trajectory.time_grid(100.0)
    torque = inverse_dynamics(
        robot,
        trajectory.position(t),
        trajectory.velocity(t),
        trajectory.acceleration(t),
        friction=False,
    )
    return np.sqrt(np.trapezoid(torque**2, t, axis=0) / trajectory.duration)


def with_arc_scales(robot: so.Robot, scales: np.ndarray) -> so.Robot:
    arcs = {}
    for name, scale in zip(("upper_arc", "lower_arc"), scales, strict=True):
        arc = getattr(robot, name)
        arcs[name] = dataclasses.replace(arc, mass=arc.mass * scale, inertia=arc.inertia * scale)
    return dataclasses.replace(robot, **arcs)


def main() -> None:
    problem = so.load_problem(ROOT / "problems" / "craniotomy_bone_flap.toml")
    trajectory = so.plan(problem, "cubic")
    robot = problem.robot
    print(f"RMS torques with the file's values: {rms_torques(robot, trajectory)} N·m")
    fit = least_squares(
        lambda s: rms_torques(with_arc_scales(robot, s), trajectory) - TARGET_RMS_NM,
        x0=[1.0, 1.0],
        bounds=([0.0, 0.0], [10.0, 10.0]),
        xtol=1e-14,
        ftol=1e-14,
    )
    calibrated = with_arc_scales(robot, fit.x)
    print(f"scales of the arcs' masses: {fit.x}")
    calibrated_rms = rms_torques(calibrated, trajectory)
    print(f"RMS torques calibrated: {calibrated_rms} N·m (target {TARGET_RMS_NM})")
    for name in ("upper_arc", "lower_arc"):
        arc = getattr(calibrated, name)
        inertia = ", ".join(f"[{', '.join(f'{v:.5g}' for v in row)}]" for row in arc.inertia)
        print(f"[{name}] mass_kg = {arc.mass:.5g}\n  inertia_kg_m2 = [{inertia}]")


if __name__ == "__main__":
    sys.exit(run_script(main))
