"""What the navigation tests share: the skull problem, a short flap on it, and the tool's
pose derived here from the paper's inverse kinematics (Eq. 2), the upper platform's frame
(Eq. 17), a ray cast with trimesh on the outer mesh, and the problem file's registration:
none of it through spm_opt's kinematics or its navigation scene."""

from __future__ import annotations

import functools
import socket
import threading
import tomllib
from pathlib import Path

import numpy as np
import trimesh

import spm_opt as so
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot
from spm_opt.navigation.link import NavigationLink
from spm_opt.problem.problem import Problem

ROOT = Path(__file__).resolve().parents[1]
SKULL_PROBLEM = ROOT / "problems" / "skull_flap.toml"


@functools.cache
def skull_problem() -> Problem:
    return so.load_problem(SKULL_PROBLEM)


@functools.cache
def short_flap() -> Problem:
    """Three points 6 mm apart along the skull problem's contour, open: a plan of about
    4 s."""
    return skull_problem().along_contour([0.0, 6.0, 12.0], [2.0, 2.0], "skull_short_flap")


@functools.cache
def file_registration() -> np.ndarray:
    """The skull problem's ``image_to_robot`` (4, 4), RAS mm to robot mm, read here."""
    table = tomllib.loads(SKULL_PROBLEM.read_text())
    return np.array(table["skull"]["image_to_robot"], dtype=float)


@functools.cache
def outer_mesh_in_robot_mm() -> trimesh.Trimesh:
    table = tomllib.loads(SKULL_PROBLEM.read_text())
    assert table["skull"]["frame"] == "RAS"
    mesh = trimesh.load_mesh(SKULL_PROBLEM.parent / table["skull"]["outer_mesh"])
    mesh.apply_transform(file_registration())
    return mesh


def tool_to_ras_expected(q: np.ndarray) -> np.ndarray:
    """ToolToRAS (4, 4), mm, at joint angles (2,), rad: the tool along the direction whose
    inverse kinematics (θ1 = atan2(−b_y, b_z), θ2 = atan2(b_x, b_z)) are q; y the upper
    arc's normal (0, cos θ1, sin θ1); x = y × z; the origin where the ray from the
    isocenter meets the outer mesh."""
    theta1, theta2 = float(q[0]), float(q[1])
    b = np.array([np.tan(theta2), -np.tan(theta1), 1.0])
    b /= np.linalg.norm(b)
    y = np.array([0.0, np.cos(theta1), np.sin(theta1)])
    x = np.cross(y, b)
    locations, _, _ = outer_mesh_in_robot_mm().ray.intersects_location(np.zeros((1, 3)), b[None, :])
    distances = np.linalg.norm(locations, axis=1)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = x, y, b
    pose[:3, 3] = b * distances.max()
    return np.linalg.inv(file_registration()) @ pose


def float32_close(received: np.ndarray, expected: np.ndarray, extra: float = 1e-6) -> bool:
    """Equal within what float32 can hold: one float32 step of each value, plus ``extra``."""
    step = np.spacing(np.abs(expected).astype(np.float32)).astype(float)
    return bool(np.all(np.abs(received - expected) <= step + extra))


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class SimulatedRun:
    """A run of the short flap on the simulated robot, on the wall clock, with the link on
    a free port; the test's thread is the operator."""

    def __init__(self, tmp_path, start_offset_deg: float = 0.0) -> None:
        self.problem = short_flap()
        self.plan = so.plan(self.problem, planner="toppra")
        start = self.plan.position(self.plan.start_time) + np.radians(start_offset_deg)
        backend = SimulatedRobot(self.problem.robot, start_rad=start, realtime=True)
        settings = ExecutionSettings(approach=start_offset_deg != 0.0)
        self.executor = Executor(self.problem, backend, settings)
        self.link = NavigationLink(self.problem, self.plan, self.executor, port=0)
        self.log = tmp_path / "run.csv"
        self.result = None
        self._go = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        self._go.wait()
        self.result = self.executor.run(self.plan, self.log)
        self.link.finished(self.result)

    def start(self) -> None:
        """The operator starts the run (after the peer connected)."""
        self._go.set()

    def __enter__(self) -> SimulatedRun:
        self.link.start()
        self._thread.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._go.set()
        self._thread.join(timeout=120.0)
        self.link.close()
