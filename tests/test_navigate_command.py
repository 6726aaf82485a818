"""``spm-opt navigate``: a flap sent from a pyigtl peer as a POINT list becomes a problem
file that plans, and the planned cut comes back as a model with the plan's points through
the registration; a registration sent as RASToRobot is the one the problem is written
with. Nothing moves."""

from __future__ import annotations

import signal
import subprocess
import sys
import tomllib

import numpy as np
import pyigtl
import pytest
from igtl_peer import Peer
from navigation_helpers import ROOT, file_registration, free_port, tool_to_ras_expected

import spm_opt as so
from spm_opt.navigation.link import PLANNED_CUT_RATE_HZ
from spm_opt.skull.markups import read_markups

pytestmark = pytest.mark.real_time


class _Navigate:
    def __init__(self, out) -> None:
        self.port = free_port()
        command = [sys.executable, "-m", "spm_opt.cli", "navigate", "--problem"]
        command += ["problems/skull_flap.toml", "--out", str(out), "--igtl", str(self.port)]
        self.process = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)

    def __enter__(self) -> Peer:
        self.peer = Peer(self.port)
        return self.peer

    def __exit__(self, *_exc: object) -> None:
        self.peer.close()
        self.process.send_signal(signal.SIGINT)
        _, self.stderr = self.process.communicate(timeout=30)


def _plan_ended(device: str):
    """The second STATUS of a PLAN command: how it ended."""
    return lambda m: (
        m.device == device and m.kind == "STATUS" and m.content[2].startswith(("planned", "failed"))
    )


def _flap() -> pyigtl.PointMessage:
    markups = read_markups(ROOT / "problems" / "skull" / "flap.mrk.json")
    return pyigtl.PointMessage(
        positions=markups.points_ras_mm.tolist(), names=list(markups.labels), device_name="Flap"
    )


def test_a_flap_from_slicer_plans_and_its_cut_comes_back(tmp_path):
    navigate = _Navigate(tmp_path)
    with navigate as peer:
        peer.wait_for(lambda m: m.device == "RunState")
        peer.send(pyigtl.StringMessage("PLAN", device_name="CMD_a"))  # before any flap
        early = peer.wait_for(lambda m: m.device == "CMD_a")
        peer.send(_flap())
        peer.send(pyigtl.StringMessage("PLAN toppra", device_name="CMD_7"))
        done = peer.wait_for(_plan_ended("CMD_7"), timeout_s=120.0)
        cut = peer.wait_for(lambda m: m.device == "PlannedCut")
    assert navigate.process.returncode == 0, navigate.stderr
    assert early.content[0] == 13  # not ready: no flap yet
    assert done.content[0] == 1, done.content
    problem = so.load_problem(tmp_path / "flap_7.toml")
    plan = so.Trajectory.from_csv(tmp_path / "flap_7_toppra.csv")
    assert problem.closed and len(problem.landmarks) == 5
    t = plan.time_grid(PLANNED_CUT_RATE_HZ)
    expected = np.array([tool_to_ras_expected(q)[:3, 3] for q in plan.position(t)])
    points, lines = cut.content
    assert points.shape == expected.shape
    np.testing.assert_allclose(points, expected, atol=1e-4)  # float32 of ~100 mm
    assert lines == [list(range(len(points)))]
    # the plan is judged as any plan is
    assert so.evaluate(problem, plan).accepted


def test_a_registration_from_slicer_is_the_one_the_flap_is_written_with(tmp_path):
    shift = np.eye(4)
    shift[:3, 3] = [0.5, -0.25, 0.0]  # mm: the image a little moved
    registration = file_registration() @ shift
    with _Navigate(tmp_path) as peer:
        peer.wait_for(lambda m: m.device == "RunState")
        peer.send(pyigtl.TransformMessage(registration, device_name="RASToRobot"))
        moved = peer.wait_for(
            lambda m: m.device == "RobotToRAS" and m is not peer.of("RobotToRAS")[0]
        )
        peer.send(_flap())
        peer.send(pyigtl.StringMessage("PLAN cubic", device_name="CMD_8"))
        done = peer.wait_for(_plan_ended("CMD_8"), timeout_s=120.0)
    assert done.content[0] == 1, done.content
    np.testing.assert_allclose(moved.content, np.linalg.inv(registration), atol=1e-4)
    written = tomllib.loads((tmp_path / "flap_8.toml").read_text())
    np.testing.assert_allclose(written["skull"]["image_to_robot"], registration, atol=1e-5)


@pytest.mark.parametrize(
    "arguments, says",
    [
        (["--igtl", "99999"], "argument --igtl: '99999': expected a TCP port, 0 to 65535"),
        (["--igtl", "taken"], "the port is taken (--igtl takes another port"),
        (["--igtl-host", "10.255.255.1"], "OpenIGTLink server on 10.255.255.1:18944"),
    ],
)
def test_a_server_that_cannot_listen_is_one_line_and_writes_nothing(tmp_path, arguments, says):
    import socket

    out = tmp_path / "out"
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        arguments = [str(taken.getsockname()[1]) if a == "taken" else a for a in arguments]
        command = [sys.executable, "-m", "spm_opt.cli", "navigate", "--problem"]
        command += ["problems/skull_flap.toml", "--out", str(out), *arguments]
        result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert says in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not out.exists()
