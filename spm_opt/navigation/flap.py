"""A flap drawn in 3D Slicer, made a problem and planned: what PLAN does.

The POINT list arrives in the image's RAS frame, mm. It is written as a markups file
(``flap_<id>.mrk.json``, RAS, a closed curve) beside a problem file (``flap_<id>.toml``):
the base problem's file with the markups file as its landmarks, segment durations for the
new flap (its arc lengths at the base problem's mean tool speed), its
paths made to point from the output folder, and, when Slicer sent a registration, that
registration as ``image_to_robot``. The problem is then loaded from that file, exactly as
``spm-opt execute --problem`` will load it, and planned; the plan is written as
``flap_<id>_<planner>.csv``. Nothing moves: a lab runs the files with ``spm-opt execute``.
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from spm_opt.base.errors import InputError
from spm_opt.base.files import write_atomically
from spm_opt.cut.contour import segment_durations_s
from spm_opt.model.params import MM
from spm_opt.model.rigid import apply
from spm_opt.navigation.link import ReceivedFlap
from spm_opt.planners import plan
from spm_opt.problem.problem import Problem, load_problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.skull.markups import markups_text

PATH_KEYS = (("robot",), ("skull", "outer_mesh"), ("skull", "inner_mesh"))
"""The problem file's keys that name files, relative to the file."""
_SAFE_ID = re.compile(r"[^A-Za-z0-9_-]")


def flap_files(
    base: Problem, flap: ReceivedFlap, image_to_robot_mm: np.ndarray, out: Path, command_id: str
) -> Path:
    """Write the flap's markups and problem files in ``out``; the problem file's path.

    Raises
    ------
    InputError
        The base problem has no file, or fewer than 3 points arrived.
    """
    if base.source is None:
        raise InputError(
            "PLAN: the problem was not loaded from a file, so there is none to base the flap on"
        )
    if len(flap.names) < 3:
        raise InputError(f"PLAN: a flap of {len(flap.names)} points; expected at least 3")
    stem = f"flap_{_SAFE_ID.sub('_', command_id)}"
    data = tomllib.loads(base.source.read_text(encoding="utf-8"))
    folder = base.source.parent
    for keys in PATH_KEYS:
        table = data
        for key in keys[:-1]:
            table = table.get(key, {})
        if isinstance(table.get(keys[-1]), str):
            table[keys[-1]] = os.path.relpath(folder / table[keys[-1]], out)
    robot_points = apply(image_to_robot_mm, flap.points_ras_mm) * MM
    speed_mm_s = base.contour.length / float(np.sum(base.segment_durations)) / MM
    data.pop("landmarks", None)
    data.update(
        name=stem,
        description=f"A flap of {len(flap.names)} points drawn in 3D Slicer ({flap.device}) "
        f"on {base.name}",
        landmarks_file=f"{stem}.mrk.json",
        closed=True,
        segment_durations_s=segment_durations_s(robot_points, True, speed_mm_s),
    )
    skull = data.get("skull")
    if isinstance(skull, dict):
        skull.pop("registration", None)
        skull["image_to_robot"] = np.asarray(image_to_robot_mm, dtype=float).tolist()
    problem_path = out / f"{stem}.toml"
    names = _unique(flap.names)
    write_atomically(
        {
            out / f"{stem}.mrk.json": markups_text(names, flap.points_ras_mm, "RAS", True),
            problem_path: _header(base) + tomli_w.dumps(data),
        }
    )
    return problem_path


def plan_flap(
    base: Problem,
    flap: ReceivedFlap,
    planner: str,
    command_id: str,
    image_to_robot_mm: np.ndarray,
    out: Path,
) -> tuple[Problem, Trajectory]:
    """PLAN: the flap's problem (written by :func:`flap_files` and loaded from it) and its
    plan by ``planner``, written beside it as ``flap_<id>_<planner>.csv``."""
    problem = load_problem(flap_files(base, flap, image_to_robot_mm, out, command_id))
    trajectory = plan(problem, planner=planner)
    trajectory.to_csv(out / f"{problem.name}_{planner}.csv")
    return problem, trajectory


def _unique(names: tuple[str, ...]) -> tuple[str, ...]:
    """The points' names, made unique and non-empty (F-1, F-2, ... where needed)."""
    seen: set[str] = set()
    unique = []
    for i, name in enumerate(names):
        label = name.strip() or f"F-{i + 1}"
        if label in seen:
            label = f"{label}-{i + 1}"
        seen.add(label)
        unique.append(label)
    return tuple(unique)


def _header(base: Problem) -> str:
    return f"# Written by spm-opt navigate from a flap drawn in 3D Slicer, on {base.source}\n"
