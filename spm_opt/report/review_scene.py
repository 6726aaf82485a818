"""What the review page and its PNG draw, in mm in the robot's frame: the skull's patch
around the flap, the landmarks, the planned contour, the planned cut coloured by its
distance from the contour, the executed cut from a log, the predicted cut of the plan's run
on a robot file's closed-loop model, and the times the robot is shown at.

The cut in a direction p (the platform's unit direction, Eq. 5 over r_u) is where the tool
meets the skull, ρ(p) p with ρ the skull's radius in that direction. The skull is drawn
:data:`SKULL_SINK_MM` inside its surface, so that the cut drawn on it stays visible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.model import kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.report.review_verdict import PREDICTED, RUN, RUN_TRUE

if TYPE_CHECKING:
    import pandas as pd

    from spm_opt.problem.problem import Problem
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.skull.surface import Skull
    from spm_opt.verify.predicted_cut import PredictedCut

SKULL_REACH = 45.0 * DEG
"""The skull is drawn this far (rad) from the flap's mean landmark direction, or farther
on a wider flap (its widest landmark's angle plus :data:`SKULL_MARGIN`)."""
SKULL_MARGIN = 15.0 * DEG
"""How far (rad) the skull drawn reaches past the flap's widest landmark."""
MAX_SKULL_FACES = 60_000
"""A mesh patch with more faces is decimated (vertex clustering) to at most this many."""
SKULL_GRID = (36, 72)
"""Rings and directions per ring of the patch drawn from the surface without a mesh."""
SKULL_SINK_MM = 0.4
"""How far inside the skull's surface it is drawn, mm."""
CONTOUR_SAMPLES = 1500
"""Points along the planned contour."""
CUT_RATE_HZ = 50.0
"""Samples of the planned cut per second of the plan (at most :data:`MAX_CUT_SAMPLES`)."""
MAX_CUT_SAMPLES = 4000
"""Most points of a cut, planned or executed."""
MEASURED = ("position_theta1_rad", "position_theta2_rad")
"""The execution log's measured joint angles."""


@dataclass(frozen=True)
class Cut:
    """A cut on the skull.

    Attributes
    ----------
    t : ndarray (N,), s
        Plan time (planned) or log time (executed) of each point.
    q : ndarray (N, 2), rad
        Joint angles.
    points : ndarray (N, 3), mm
        Where the tool meets the skull.
    deviation : ndarray (N,), mm
        Each point's distance from the planned contour.
    """

    t: np.ndarray
    q: np.ndarray
    points: np.ndarray
    deviation: np.ndarray


@dataclass(frozen=True)
class ReviewScene:
    """Everything the review draws, mm in the robot's frame.

    Attributes
    ----------
    flap_direction : ndarray (3,)
        The landmarks' mean direction from the isocenter, a unit vector.
    skull_vertices : ndarray (V, 3), mm
    skull_faces : ndarray (F, 3), int
        The skull's patch around the flap, triangles of ``skull_vertices``.
    landmark_names : tuple of str
    landmarks : ndarray (n, 3), mm
    contour : ndarray (CONTOUR_SAMPLES, 3), mm
    planned : Cut
    executed : Cut or None
        The measured joint angles of a log, from its plan phase's start on.
    predicted : Cut or None
        The closed-loop model's true joint angles over the plan's predicted run.
    """

    flap_direction: np.ndarray
    skull_vertices: np.ndarray
    skull_faces: np.ndarray
    landmark_names: tuple[str, ...]
    landmarks: np.ndarray
    contour: np.ndarray
    planned: Cut
    executed: Cut | None
    predicted: Cut | None = None

    def drawn(self, key: str) -> Cut:
        """The cut a judged cut's violations are marked on (its
        :class:`~spm_opt.report.review_verdict.Judged` key): the predicted cut for the
        prediction's, the executed one (the measured angles) for a run's, if drawn, else
        the planned cut."""
        if key == PREDICTED and self.predicted is not None:
            return self.predicted
        if key in (RUN, RUN_TRUE) and self.executed is not None:
            return self.executed
        return self.planned


def review_scene(
    problem: Problem,
    skull: Skull,
    trajectory: Trajectory,
    log: pd.DataFrame | None = None,
    predicted: PredictedCut | None = None,
) -> ReviewScene:
    """The scene of a plan, of its execution when ``log`` (an execution log's table,
    :func:`spm_opt.execution.log.read_execution_log`) is given, and of its predicted run
    when ``predicted`` is."""
    directions = problem.landmarks / np.linalg.norm(problem.landmarks, axis=1, keepdims=True)
    centre = directions.mean(axis=0)
    centre /= np.linalg.norm(centre)
    widest = float(np.max(np.arccos(np.clip(directions @ centre, -1.0, 1.0))))
    reach = max(SKULL_REACH, widest + SKULL_MARGIN)
    if skull.outer_mesh is None:
        vertices, faces = _surface_patch(skull, centre, reach)
    else:
        vertices, faces = _mesh_patch(skull, centre, reach)
    radii = np.linalg.norm(vertices, axis=1, keepdims=True)
    contour = problem.contour
    n = int(np.clip(np.ceil(trajectory.duration * CUT_RATE_HZ), 200, MAX_CUT_SAMPLES))
    t = np.linspace(trajectory.start_time, trajectory.end_time, n)
    executed = None if log is None else _cut(problem, skull, *executed_angles(log))
    return ReviewScene(
        flap_direction=centre,
        skull_vertices=vertices * (1.0 - SKULL_SINK_MM / radii),
        skull_faces=faces,
        landmark_names=tuple(problem.landmark_names),
        landmarks=problem.landmarks / MM,
        contour=contour.point_at(np.linspace(0.0, contour.length, CONTOUR_SAMPLES)) / MM,
        planned=_cut(problem, skull, t, trajectory.position(t)),
        executed=executed,
        predicted=None if predicted is None else _cut(problem, skull, *_thinned(predicted)),
    )


def executed_angles(log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Times (N,), s, and measured joint angles (N, 2), rad, of a log's rows from its plan
    phase's start on, those whose read failed left out (at most :data:`MAX_CUT_SAMPLES`,
    evenly spaced)."""
    import pandas as pd

    phase = log["phase"].astype(str).to_numpy()
    plan_rows = np.flatnonzero(phase == "plan")
    if plan_rows.size == 0:
        raise InputError("log: no plan rows (the run stopped before its plan began)")
    rows = log.iloc[plan_rows[0] :]
    columns = ["time_s", *MEASURED]
    values = np.column_stack([pd.to_numeric(rows[c], errors="coerce") for c in columns])
    values = values[np.all(np.isfinite(values), axis=1)]
    if len(values) < 2:
        raise InputError("log: fewer than two rows of measured joint angles in the plan phase")
    step = int(np.ceil(len(values) / MAX_CUT_SAMPLES))
    values = values[::step]
    return values[:, 0], values[:, 1:]


def _thinned(predicted: PredictedCut) -> tuple[np.ndarray, np.ndarray]:
    """A predicted run's times (N,), s, and joint angles (N, 2), rad, at most
    :data:`MAX_CUT_SAMPLES` of them, evenly spaced."""
    step = int(np.ceil(len(predicted.time_s) / MAX_CUT_SAMPLES))
    return predicted.time_s[::step], predicted.angles_rad[::step]


def _cut(problem: Problem, skull: Skull, t: np.ndarray, q: np.ndarray) -> Cut:
    p = kinematics.forward_kinematics(q, 1.0)
    points = skull.surface.radius(p)[:, None] * p
    return Cut(t=t, q=q, points=points / MM, deviation=problem.contour.deviation(p) / MM)


def _surface_patch(skull: Skull, centre: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3), mm, and faces (F, 3) of the surface over the cap of ``reach`` (rad)
    about ``centre``: rings of :data:`SKULL_GRID` directions, radii from the surface."""
    rings, around = SKULL_GRID
    first = np.cross(centre, np.eye(3)[np.argmin(np.abs(centre))])
    first /= np.linalg.norm(first)
    second = np.cross(centre, first)
    polar = np.linspace(0.0, reach, rings + 1)[1:, None]
    azimuth = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)[None, :]
    tangent = np.cos(azimuth)[..., None] * first + np.sin(azimuth)[..., None] * second
    ring_directions = np.cos(polar)[..., None] * centre + np.sin(polar)[..., None] * tangent
    directions = np.vstack([centre, ring_directions.reshape(-1, 3)])
    vertices = skull.surface.radius(directions)[:, None] * directions / MM
    ring = 1 + np.arange(rings)[:, None] * around
    this, following = np.arange(around)[None, :], (np.arange(around)[None, :] + 1) % around
    fan = np.column_stack([np.zeros(around, int), 1 + following[0], 1 + this[0]])
    a, b = ring[:-1] + this, ring[:-1] + following
    c, d = ring[1:] + this, ring[1:] + following
    quads = np.concatenate([np.stack([a, b, d], -1), np.stack([a, d, c], -1)]).reshape(-1, 3)
    return vertices, np.vstack([fan, quads])


def _mesh_patch(skull: Skull, centre: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3), mm, and faces (F, 3) of the outer mesh whose centroids lie within
    ``reach`` (rad) of ``centre``, decimated to :data:`MAX_SKULL_FACES`."""
    mesh = skull.outer_mesh
    vertices = np.asarray(mesh.vertices, dtype=float) / MM
    faces = np.asarray(mesh.faces, dtype=np.int64)
    centroids = vertices[faces].mean(axis=1)
    cosine = centroids @ centre / np.linalg.norm(centroids, axis=1)
    faces = faces[cosine >= np.cos(reach)]
    if len(faces) == 0:
        raise InputError("skull: the outer mesh has no faces around the flap's landmarks")
    used, faces = np.unique(faces, return_inverse=True)
    vertices, faces = vertices[used], faces.reshape(-1, 3)
    return decimate(vertices, faces, MAX_SKULL_FACES)


def decimate(
    vertices: np.ndarray, faces: np.ndarray, max_faces: int
) -> tuple[np.ndarray, np.ndarray]:
    """A mesh of at most ``max_faces`` faces by vertex clustering: vertices (V, 3) merged
    into their cell's mean on a grid coarsened until few enough faces stay distinct.

    Parameters
    ----------
    vertices : ndarray (V, 3)
        In any unit.
    faces : ndarray (F, 3), int
    max_faces : int

    Returns
    -------
    vertices, faces : ndarray (V', 3), ndarray (F', 3)
        The same mesh, unchanged if it had no more than ``max_faces`` faces.
    """
    if len(faces) <= max_faces:
        return vertices, faces
    sides = vertices[faces[:, 1:]] - vertices[faces[:, :1]]
    area = 0.5 * np.sum(np.linalg.norm(np.cross(sides[:, 0], sides[:, 1]), axis=1))
    cell = np.sqrt(2.0 * area / max_faces)
    while True:
        keys = np.floor((vertices - vertices.min(axis=0)) / cell).astype(np.int64)
        _, cluster = np.unique(keys, axis=0, return_inverse=True)
        cluster = cluster.reshape(-1)
        merged = cluster[faces]
        distinct = (
            (merged[:, 0] != merged[:, 1])
            & (merged[:, 1] != merged[:, 2])
            & (merged[:, 0] != merged[:, 2])
        )
        merged = merged[distinct]
        _, first = np.unique(np.sort(merged, axis=1), axis=0, return_index=True)
        if len(first) <= max_faces:
            break
        cell *= 1.2
    count = np.bincount(cluster)
    centres = np.stack([np.bincount(cluster, vertices[:, k]) for k in range(3)], -1)
    return centres / count[:, None], merged[np.sort(first)]
