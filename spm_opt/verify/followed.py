"""How the joints followed a stream: an execution log's plan-phase cycles, their plan
times, references and positions (the readings, or a plant's true state)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np


@dataclasses.dataclass(frozen=True)
class Followed:
    """How the joints followed a stream, per plan-phase cycle.

    Attributes
    ----------
    plan_time_s : ndarray (M,), s
        The plan time each cycle's reference was sampled at.
    reference_rad : ndarray (M, 2), rad
        The stream's reference at that time.
    position_rad : ndarray (M, 2), rad
        The joints' position at the cycle: the model's true state, or the robot's reading.
    """

    plan_time_s: np.ndarray
    reference_rad: np.ndarray
    position_rad: np.ndarray


def followed_in_log(table: Any, trace: dict[str, np.ndarray] | None = None) -> Followed:
    """The plan-phase cycles of an execution log's ``table`` whose read succeeded, their
    positions the readings or, with a plant's ``trace`` (on the log's clock), its true
    state at the cycles' times."""
    rows = table[table["phase"].astype(str) == "plan"]
    columns = ("theta1", "theta2")
    position = rows[[f"position_{j}_rad" for j in columns]].to_numpy(float)
    reference = rows[[f"reference_{j}_rad" for j in columns]].to_numpy(float)
    plan_time = rows["plan_time_s"].to_numpy(float)
    if trace is not None:
        times = rows["time_s"].to_numpy(float)
        position = np.column_stack(
            [np.interp(times, trace["time_s"], trace["position_rad"][:, j]) for j in range(2)]
        )
    read = np.all(np.isfinite(position), axis=1) & np.isfinite(plan_time)
    return Followed(plan_time[read], reference[read], position[read])
