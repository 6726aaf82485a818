"""A simulated optical tracker, for tests and for planning a calibration: it watches a
marker on the simulated robot's tool from a frame nobody told the robot.

It samples the plant's true state (:class:`~spm_opt.execution.plant.StateTrace`, whose
positions are the model's joint coordinates of the tool's true direction) at its own
rate, puts the marker at ``marker_distance_mm`` along the tool, maps it by a seeded
random rigid transform to the tracker's frame, and adds:

- a localisation error per sample, isotropic Gaussian of ``fle_mm`` 3-D RMS (σ = FLE/√3
  per coordinate);
- a bias per pose, ``bias_mm`` 3-D RMS, the same for every sample of a still window (a
  tracker's error that varies over its volume: averaging does not remove it);
- dropouts: each sample lost with probability ``dropout`` (written as an occluded frame).

It gives the generic point CSV (``time_s,x_mm,y_mm,z_mm``), read as a lab's export is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from spm_opt.calibration.tracker_files import point_csv_text
from spm_opt.model import kinematics

MM = 1e-3
STILL_RAD_S = 1e-4
"""Joint rate below which the simulated tracker counts the robot as still (for the bias)."""


@dataclass(frozen=True)
class SimulatedTracker:
    """The tracker's settings (mm, Hz; ``dropout`` a probability; ``seed`` for all noise
    and for the tracker-to-robot transform)."""

    marker_distance_mm: float = 200.0
    fle_mm: float = 0.2
    bias_mm: float = 0.0
    rate_hz: float = 60.0
    dropout: float = 0.02
    seed: int = 0

    def transform(self) -> tuple[np.ndarray, np.ndarray]:
        """The robot-to-tracker rotation (3, 3) and translation (3,), m: seeded, anywhere
        within 2 m."""
        rng = np.random.default_rng([self.seed, 1])
        rotation = Rotation.random(random_state=rng).as_matrix()
        return rotation, rng.uniform(-2.0, 2.0, 3)

    def observe(self, trace: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The tracker's times (k,), s, and marker positions (k, 3), m, NaN where lost,
        from a trace's arrays (:meth:`StateTrace.arrays`)."""
        rng = np.random.default_rng([self.seed, 2])
        times = trace["time_s"]
        samples = np.arange(times[0], times[-1], 1.0 / self.rate_hz)
        q = np.stack([np.interp(samples, times, trace["position_rad"][:, j]) for j in range(2)], 1)
        rate = np.max(
            np.abs([np.interp(samples, times, trace["velocity_rad_s"][:, j]) for j in range(2)]),
            axis=0,
        )
        rotation, translation = self.transform()
        points = kinematics.forward_kinematics(q, self.marker_distance_mm * MM)
        points = points @ rotation.T + translation
        points += rng.normal(0.0, self.fle_mm * MM / np.sqrt(3.0), points.shape)
        still = rate < STILL_RAD_S
        window = np.cumsum(np.diff(still.astype(int), prepend=0) == 1)  # a count per window
        biases = rng.normal(0.0, self.bias_mm * MM / np.sqrt(3.0), (int(window.max()) + 1, 3))
        points += np.where(still[:, None], biases[window], 0.0)
        points[rng.random(len(points)) < self.dropout] = np.nan
        return samples, points

    def csv_text(self, trace: dict[str, np.ndarray]) -> str:
        """:meth:`observe` as the generic point CSV's text (mm; lost frames empty)."""
        return point_csv_text(*self.observe(trace))
