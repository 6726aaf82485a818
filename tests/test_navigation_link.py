"""The navigation link during a run on the simulated robot, seen by a pyigtl peer: the
tool's pose agrees with the log's measured angles through the paper's kinematics and the
registration, at the stated rate; the states follow the run's phases; models arrive on
every connection; HOLD, RESUME and STOP act as the keys and Ctrl-C do; nothing received
starts motion."""

from __future__ import annotations

import time

import numpy as np
import pyigtl
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from igtl_peer import Peer
from navigation_helpers import (
    SimulatedRun,
    file_registration,
    float32_close,
    skull_problem,
    tool_to_ras_expected,
)

import spm_opt as so
from spm_opt.execution.log import read_log
from spm_opt.navigation import scene
from spm_opt.navigation.link import POSE_RATE_HZ


@settings(max_examples=40, deadline=None)
@given(
    theta1=st.floats(np.radians(-25.0), np.radians(25.0)),
    theta2=st.floats(np.radians(-25.0), np.radians(25.0)),
)
def test_the_tool_pose_is_the_paper_kinematics_through_the_registration(theta1, theta2):
    problem = skull_problem()
    to_ras = scene.robot_to_ras(scene.image_to_robot(problem))
    pose = scene.tool_to_ras(problem, np.array([[theta1, theta2]]), to_ras)[0]
    np.testing.assert_allclose(pose, tool_to_ras_expected(np.array([theta1, theta2])), atol=1e-7)


def test_a_problem_without_a_registration_is_shown_in_the_robots_frame():
    problem = so.load_problem("problems/craniotomy_bone_flap.toml")
    assert np.array_equal(scene.image_to_robot(problem), np.eye(4))
    assert np.allclose(scene.image_to_robot(skull_problem()), file_registration())


@pytest.mark.real_time
def test_the_stream_is_the_logged_run(tmp_path):
    with SimulatedRun(tmp_path, start_offset_deg=0.5) as run:
        peer = Peer(run.link.server.port)
        peer.wait_for(lambda m: m.device == "PlannedCut")
        run.start()
        # halfway through, the client goes and a new one comes: the run does not notice
        peer.wait_for(lambda m: m.device == "RunState" and m.content[1] == "running")
        peer.close()
        second = Peer(run.link.server.port)
        second.wait_for(lambda m: m.device == "RunState" and m.content[1] in ("at rest", "fault"))
        second.close()
    assert run.result is not None and run.result.succeeded, run.result.reason

    table, _ = read_log(run.log)
    times = table["time_s"].to_numpy()
    q = table[["position_theta1_rad", "position_theta2_rad"]].to_numpy()
    poses = peer.of("ToolToRAS") + second.of("ToolToRAS")
    assert len(poses) > 100
    for message in poses:
        row = int(np.argmin(np.abs(times - message.timestamp_s)))  # each frame names its row
        assert abs(times[row] - message.timestamp_s) < 2e-6
        assert float32_close(message.content, tool_to_ras_expected(q[row])), message.timestamp_s

    # the rate: frames per second of the log's clock while the joints were read
    stamps = np.array([m.timestamp_s for m in second.of("ToolToRAS")])
    assert len(stamps) / (stamps[-1] - stamps[0]) >= 30.0
    assert np.median(np.diff(stamps)) == pytest.approx(1.0 / POSE_RATE_HZ, abs=0.011)

    # the states: the first peer from before the start, the second from halfway to the end
    assert peer.states()[:3] == ["ready", "approach", "running"]
    assert second.states() == ["running", "settling", "at rest"]

    # every connection gets the models; the planned cut is the plan through the registration
    for client in (peer, second):
        devices = {m.device for m in client.of("RobotToRAS") + client.of("Contour")}
        assert devices == {"RobotToRAS", "Contour"}
    planned = second.of("PlannedCut")[0].content[0]
    t = run.plan.time_grid(20.0)
    expected = np.array([tool_to_ras_expected(p)[:3, 3] for p in run.plan.position(t)])
    assert planned.shape == expected.shape
    np.testing.assert_allclose(planned, expected, atol=1e-4)  # float32 of ~100 mm


@pytest.mark.real_time
def test_hold_resume_and_stop_act_as_the_keys(tmp_path):
    with SimulatedRun(tmp_path) as run:
        peer = Peer(run.link.server.port)
        peer.wait_for(lambda m: m.device == "RunState")
        run.start()
        peer.wait_for(lambda m: m.device == "RunState" and m.content[1] == "running")
        peer.send(pyigtl.StringMessage("START", device_name="CMD_9"))
        denied = peer.wait_for(lambda m: m.device == "CMD_9")
        peer.send(pyigtl.StringMessage("HOLD", device_name="CMD_1"))
        peer.wait_for(lambda m: m.device == "RunState" and m.content[1] == "held")
        resumed = peer.received()  # the "running" from before the hold must not count
        peer.send(pyigtl.StringMessage("resume", device_name="CMD_2"))
        peer.wait_for(lambda m: m.device == "RunState" and m.content[1] == "running", since=resumed)
        sent = time.monotonic()
        peer.send(pyigtl.StringMessage("STOP", device_name="CMD_3"))
        stopping = peer.wait_for(lambda m: m.device == "RunState" and m.content[1] == "stopping")
        peer.wait_for(lambda m: m.device == "RunState" and m.content[1] in ("stopped", "fault"))
        peer.close()
    assert denied.content[0] == 5  # access denied: nothing received starts motion
    acks = {m.device: m.content for m in peer.of("ACK_1") + peer.of("ACK_2") + peer.of("ACK_3")}
    assert acks == {"ACK_1": "HOLD", "ACK_2": "resume", "ACK_3": "STOP"}
    result = run.result
    assert result is not None and not result.completed
    assert result.reason.startswith("interrupted (STOP from the navigation link")
    assert result.stop is not None and result.stop.at_rest
    assert peer.states()[-1] == "stopped"
    events = [e["event"] for e in result.feed_events]
    assert "hold" in events and "resume" in events[events.index("hold") :]
    assert stopping.arrived_s - sent < 0.5
