"""The Dynamixel backend through the official SDK, against the emulator on a pseudo-terminal."""

from __future__ import annotations

import contextlib
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_library_cache import wait_until

from spm_opt.base.errors import CommunicationError, DeviceError, InputError
from spm_opt.execution import dynamixel
from spm_opt.execution.backend import hardware_error_names
from spm_opt.execution.dynamixel import (
    MAX_ID,
    DynamixelRobot,
    stuffing_safe_goals,
    sync_write_body,
)
from spm_opt.execution.emulator import (
    CorruptReplies,
    DropReplies,
    Emulator,
    Faults,
    Overload,
    RefusedWrites,
    spawn_emulator,
)
from spm_opt.execution.plant import PlantSettings
from spm_opt.model import dynamics
from spm_opt.model.actuator import ACTUATORS
from spm_opt.problem.problem import load_problem

pytestmark = pytest.mark.real_time

dynamixel_sdk = pytest.importorskip("dynamixel_sdk")

L54 = ACTUATORS["L54-50-S500-R"]
PATTERN = b"\xff\xff\xfd"
LIMIT = L54.pulses_per_rev // 2
INT32 = st.integers(-(2**31) + 600, 2**31 - 601)
PROBLEM = Path(__file__).resolve().parents[1] / "problems" / "craniotomy_hardware.toml"


class CapturePort:
    """What the SDK's packet handler needs of a port, keeping what it writes."""

    is_using = False

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def clearPort(self) -> None:  # noqa: N802 (the SDK's name)
        pass

    def writePort(self, packet: list[int]) -> int:  # noqa: N802
        self.sent.append(bytes(packet))
        return len(packet)


def sdk_sync_write(ids: tuple[int, ...], goals: list[int]) -> bytes:
    """The packet the SDK's GroupSyncWrite emits for these goals."""
    port = CapturePort()
    group = dynamixel_sdk.GroupSyncWrite(port, dynamixel_sdk.PacketHandler(2.0), 596, 4)
    for dxl_id, goal in zip(ids, goals, strict=True):
        group.addParam(dxl_id, list(goal.to_bytes(4, "little", signed=True)))
    assert group.txPacket() == dynamixel_sdk.COMM_SUCCESS
    return port.sent[0]


# ------------------------------------------------------------ the stuffing guard
def test_the_clients_copies_of_the_tables_agree_with_the_emulators():
    """The client types its addresses and protocol constants apart from the emulator's
    (an independent check); here the two copies meet."""
    from spm_opt.execution import protocol
    from spm_opt.execution.emulator import MODEL_NUMBER
    from spm_opt.execution.emulator.control_table import ITEMS

    by_name = {item.name: item.address for item in ITEMS}
    assert {name: by_name[name] for name in dynamixel.ITEM_NAMES.values()} == {
        name: address for address, name in dynamixel.ITEM_NAMES.items()
    }
    assert dynamixel.ADDR_GOAL_POSITION == by_name["Goal Position"]
    assert dynamixel.MODEL_NUMBERS["L54-50-S500-R"] == MODEL_NUMBER
    assert dynamixel.INST_SYNC_WRITE == protocol.Instruction.SYNC_WRITE
    assert (dynamixel.BROADCAST_ID, dynamixel.MAX_ID) == (protocol.BROADCAST_ID, protocol.MAX_ID)
    assert dynamixel.ALERT_BIT == protocol.ALERT
    assert protocol.HEADER.startswith(dynamixel.HEADER_PATTERN)


def test_the_sdk_sends_ff_ff_fd_unstuffed():
    """The defect the guard exists for: -131073 goes out as FF FF FD FF, LEN unchanged."""
    packet = sdk_sync_write((1, 2), [-131073, 0])
    assert packet[4:-2] == sync_write_body((1, 2), [-131073, 0])
    assert packet.find(PATTERN, 1) == 13  # goal 1's bytes, not followed by a stuffed FD
    assert packet[5] == 17 and len(packet) == 7 + 17  # LEN as if nothing needed stuffing


def test_guard_nudges_the_one_bad_goal_in_range_by_one_pulse_toward_the_previous_goal():
    assert stuffing_safe_goals((1, 2), [-131073, 5]) == [-131072, 5]
    assert stuffing_safe_goals((1, 2), [0, -131073], previous=[0, -140_000]) == [0, -131074]
    assert stuffing_safe_goals((1, 2), [-131073, -131073], previous=[0, -131073]) == [
        -131072,
        -131072,
    ]
    bad = [
        g for g in range(-LIMIT, LIMIT + 1, 1) if PATTERN in g.to_bytes(4, "little", signed=True)
    ]
    assert bad == [-131073]


@settings(max_examples=400, deadline=None)
@given(
    ids=st.lists(st.integers(0, MAX_ID), min_size=2, max_size=2, unique=True),
    goals=st.lists(
        st.one_of(INT32, st.sampled_from([-131073, 0xFDFFFF, -0x02000001, 0x7FFDFFFF])),
        min_size=2,
        max_size=2,
    ),
    previous=st.none() | st.lists(INT32, min_size=2, max_size=2),
)
def test_guard_leaves_no_ff_ff_fd_in_any_window_the_sdk_stuffs(ids, goals, previous):
    safe = stuffing_safe_goals(ids, goals, previous)
    packet = sdk_sync_write(tuple(ids), safe)
    # header through the last parameter: the only FF FF FD is the header's
    assert packet[:-2].find(PATTERN, 1) == -1
    for goal, sent in zip(goals, safe, strict=True):
        if PATTERN not in goal.to_bytes(4, "little", signed=True):
            assert sent == goal
        if abs(goal) <= LIMIT:
            assert abs(sent - goal) <= 1
        # the nearest safe value: every value strictly closer would have needed stuffing
        for closer in range(goal - abs(sent - goal) + 1, goal + abs(sent - goal)):
            assert PATTERN in closer.to_bytes(4, "little", signed=True)


# ------------------------------------------------------------------ bad inputs
@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"baud": 250_000}, "baud"),
        ({"baud": 4_500_000}, "baud"),
        ({"ids": (1, 1)}, "ids"),
        ({"ids": (1, 253)}, "ids"),
        ({"retries": -1}, "retries"),
        ({"timeout_s": 0.0}, "timeout_s"),
        ({"write_timeout_s": 0.0}, "write_timeout_s"),
    ],
)
def test_bad_settings_are_input_errors_naming_the_field(kwargs, field):
    with pytest.raises(InputError, match=rf"^{field}: "):
        DynamixelRobot(L54, "/dev/null", **kwargs)


def test_a_port_that_does_not_exist_is_an_input_error():
    robot = DynamixelRobot(L54, "/dev/no-such-dynamixel-port")
    with pytest.raises(InputError, match=r"^port: '/dev/no-such-dynamixel-port' does not exist"):
        robot.connect()
    robot.close()


def test_write_goal_refuses_goals_beyond_the_position_limits_without_a_port():
    robot = DynamixelRobot(L54, "/dev/null")
    with pytest.raises(InputError, match=r"^position_rad: 3.2 rad \(184051 pulse\) for id 1; "):
        robot.write_goal(np.array([3.2, 0.0]))
    with pytest.raises(InputError, match=r"limits -180692…180692 pulse$"):
        robot.write_goal(np.array([0.0, -3.2]))
    with pytest.raises(InputError, match=r"^position_rad: "):
        robot.write_goal(np.array([np.nan, 0.0]))


def test_read_and_write_need_a_connection():
    robot = DynamixelRobot(L54, "/dev/null")
    with pytest.raises(CommunicationError, match="call connect"):
        robot.read()
    with pytest.raises(CommunicationError, match="call connect"):
        robot.write_goal(np.zeros(2))
    robot.close()


# ------------------------------------------------------------- against the emulator
@pytest.fixture(scope="module", autouse=True)
def quick_thread_switches():
    """With the emulator in a thread of this process, a short switch interval keeps the
    GIL from delaying its replies (the SDK's own calls poll the port in a busy loop)."""
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    yield
    sys.setswitchinterval(interval)


@pytest.fixture(scope="module")
def robot():
    return load_problem(PROBLEM).robot


@contextlib.contextmanager
def connected(robot, start_rad=(0.0, 0.0), faults=None, plant_settings=None, **kwargs):
    """An in-process emulator and a connected backend on it."""
    with Emulator(
        robot, start_rad=np.array(start_rad), faults=faults, plant_settings=plant_settings
    ) as emulator:
        backend = DynamixelRobot(robot.actuator, emulator.device, **kwargs)
        backend.connect()
        try:
            yield emulator, backend
        finally:
            backend.close()


def reads_for(backend, seconds):
    """Measurements every 10 ms for ``seconds``."""
    measurements = []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        measurements.append(backend.read())
        time.sleep(0.01)
    return measurements


def test_connect_checks_both_actuators_enables_torque_and_reads_the_start(robot):
    start = (0.3, -0.2)
    with connected(robot, start) as (emulator, backend):
        assert emulator.plant.torque_enabled.all()
        measurement = backend.read()
        np.testing.assert_allclose(measurement.position_rad, start, atol=5e-3)  # sag under gravity
        assert measurement.hardware_error == (0, 0)
        # Present Current alone (2 bytes at 621): the holding current, within the plant's
        # noise (8 mA) and a unit of rounding, and the same through the 12-byte read
        holding = robot.actuator.current_map.current(
            dynamics.gravity_torque(robot, emulator.plant.position_rad[None, :])[0]
        )
        for current in (backend.read_current(0.1), measurement.current_a):
            np.testing.assert_allclose(current, holding, atol=0.05)
        described = backend.describe()
        assert described["backend"] == "dynamixel"
        assert described["model_numbers"] == [38152, 38152]
        assert described["firmware_versions"] == [0, 0]
        assert described["communication_failures"] == {
            "connect": 0,
            "read": 0,
            "current read": 0,
            "write": 0,
        }
        json.dumps(described)
    # closing leaves the actuators holding (torque stays on); a second close does nothing
    assert emulator.plant.torque_enabled.all()
    backend.close()


def test_goals_move_the_arm_and_negative_values_read_signed(robot):
    """Moving toward negative goals: positions, velocities (and noisy currents) < 0."""
    start, goal = np.array([-0.5, -0.2]), np.array([-0.8, -0.5])
    noisy = PlantSettings(current_noise_a=0.3)
    with connected(robot, start, plant_settings=noisy) as (emulator, backend):
        backend.write_goal(goal)
        measurements = reads_for(backend, 0.3)
    positions = np.array([m.position_rad for m in measurements])
    velocities = np.array([m.velocity_rad_s for m in measurements])
    currents = np.array([m.current_a for m in measurements])
    assert np.all(np.abs(positions[-1] - goal) < 0.3 * np.abs(goal - start))
    assert np.all(positions < 0.0) and np.all(np.diff(positions, axis=0) < 1e-4)
    assert np.all(velocities.min(axis=0) < -0.5)
    assert np.all(np.abs(velocities) < 5.0)  # read unsigned, -1 unit would be 8.9e5 rad/s
    assert currents.min() < -0.2 and np.all(np.abs(currents) < 5.0)


def test_a_goal_that_would_need_stuffing_arrives_nudged_and_counted(robot, caplog):
    caplog.set_level(logging.DEBUG, logger="spm_opt.execution.dynamixel")
    with connected(robot) as (emulator, backend):
        backend.write_goal(robot.actuator.angle(np.array([-131_073, 1000])))
        time.sleep(0.02)
        arrived = robot.actuator.pulses(emulator.plant.goal_position_rad)
        assert arrived.tolist() == [-131_072, 1000]  # toward the previous goal, 0
        assert backend.nudge_count == 1 and backend.describe()["nudge_count"] == 1
        assert "goal -131073 pulse sent as -131072" in caplog.text


@pytest.mark.parametrize(
    ("faults", "message"),
    [
        (Faults(drop=DropReplies(count=1)), "There is no status packet"),
        (Faults(crc=CorruptReplies(count=1)), "Incorrect status packet"),
    ],
)
def test_a_lost_or_corrupt_reply_is_a_communication_error(robot, faults, message):
    with connected(robot, faults=faults) as (_, backend):
        backend.write_goal(np.zeros(2))  # starts the faults' clock
        with pytest.raises(CommunicationError, match=rf"^id 1: .*{message}"):
            backend.read()
        backend.read()
        assert backend.describe()["communication_failures"]["read"] == 1


def test_a_retry_hides_one_lost_reply_but_counts_it(robot):
    faults = Faults(drop=DropReplies(count=1))
    with connected(robot, faults=faults, retries=1, timeout_s=0.01) as (_, backend):
        backend.write_goal(np.zeros(2))
        backend.read()
        assert backend.describe()["communication_failures"]["read"] == 1


def test_a_stalled_line_fails_write_goal_within_its_timeout_and_counts_it(robot):
    """A sync write gets no reply: its failure is the port's. While the line takes no byte,
    ``write_goal`` fails after ``write_timeout_s`` (it would otherwise wait for ever), its
    goal never arrives, and it is counted; once the line moves again, goals arrive. Each
    write waits for the emulator's line to be stopped, or to move again: pyserial waits
    for room after every write, even a whole one, so a line stopped just after a goal
    arrived failed the write that delivered it (twice in full runs, when the second write
    was timed by the host's clock instead)."""
    faults = Faults(write=RefusedWrites(at=0.05, seconds=0.4))
    with connected(robot, faults=faults) as (emulator, backend):
        backend.write_goal(np.zeros(2))  # starts the faults' clock
        assert wait_until(lambda: emulator.line_suspended, 30.0)
        start = time.perf_counter()
        with pytest.raises(CommunicationError, match=r"^port: .*Write timeout"):
            backend.write_goal(np.full(2, 0.01))
        assert time.perf_counter() - start < 0.2
        with pytest.raises(CommunicationError, match=r"^port: .*Write timeout"):
            backend.read()  # its instruction cannot go out either
        assert np.all(emulator.plant.goal_position_rad == 0.0)
        assert wait_until(lambda: not emulator.line_suspended, 30.0)
        backend.write_goal(np.full(2, 0.01))
        time.sleep(0.02)
        np.testing.assert_allclose(emulator.plant.goal_position_rad, 0.01, atol=2e-5)
        failures = backend.describe()["communication_failures"]
        assert failures == {"connect": 0, "read": 1, "current read": 0, "write": 1}


def test_an_overload_shows_in_the_next_read_and_blocks_the_next_connect(robot):
    faults = Faults(overload=(Overload(id=2, at=0.0),))
    with connected(robot, faults=faults) as (emulator, backend):
        backend.write_goal(np.zeros(2))  # the overload comes with the next packet
        error = backend.read().hardware_error
        assert error == (0, 1 << 5) and hardware_error_names(error[1]) == ["overload"]
        assert backend.read().hardware_error == error  # it stays until a reboot
        with pytest.raises(DeviceError, match=r"^id 2: Hardware Error Status 0x20 \(overload\)"):
            backend.connect()
        backend.reboot(2)
        backend.connect()
        assert emulator.plant.torque_enabled.all()
        assert backend.read().hardware_error == (0, 0)


def test_a_wrong_model_number_is_an_input_error(robot, monkeypatch):
    monkeypatch.setitem(dynamixel.MODEL_NUMBERS, L54.model, 1234)
    with Emulator(robot) as emulator:
        backend = DynamixelRobot(robot.actuator, emulator.device)
        with pytest.raises(InputError, match=r"^ids: id 1 .* model number 38152; expected 1234"):
            backend.connect()
        assert not emulator.plant.torque_enabled.any()


def test_a_missing_id_is_a_communication_error_naming_it(robot):
    with Emulator(robot) as emulator:
        backend = DynamixelRobot(robot.actuator, emulator.device, ids=(1, 3))
        with pytest.raises(CommunicationError, match=r"^id 3: ping failed .*no status packet"):
            backend.connect()


def configure(device, dxl_id, address, value, size):
    """Write one control-table item with the SDK (torque is off: EEPROM is writable)."""
    port = dynamixel_sdk.PortHandler(device)
    port.openPort()
    packets = dynamixel_sdk.PacketHandler(2.0)
    data = list(value.to_bytes(size, "little", signed=True))
    assert packets.writeTxRx(port, dxl_id, address, size, data) == (0, 0)
    port.closePort()


def test_an_actuator_not_in_position_mode_is_refused(robot):
    with Emulator(robot) as emulator:
        configure(emulator.device, 2, 11, 1, 1)
        backend = DynamixelRobot(robot.actuator, emulator.device)
        with pytest.raises(InputError, match=r"^id 2: Operating Mode is 1 \(velocity\)"):
            backend.connect()
        assert not emulator.plant.torque_enabled.any()


def test_goals_are_checked_against_the_limits_the_actuators_hold(robot):
    with Emulator(robot) as emulator:
        configure(emulator.device, 2, 40, -50_000, 4)  # Min Position Limit of θ2
        backend = DynamixelRobot(robot.actuator, emulator.device)
        backend.connect()
        assert backend.describe()["position_limits_pulses"] == [
            [-180_692, 180_692],
            [-50_000, 180_692],
        ]
        with pytest.raises(InputError, match=r"for id 2; .* -50000…180692 pulse$"):
            backend.write_goal(robot.actuator.angle(np.array([0, -50_001])))
        backend.write_goal(robot.actuator.angle(np.array([-50_001, -50_000])))
        backend.close()


@pytest.mark.slow
def test_cycles_against_the_emulator_in_a_child_process(robot):
    with spawn_emulator(problem_file=PROBLEM, start_deg=(10.0, -10.0)) as child:
        backend = DynamixelRobot(robot.actuator, child.device)
        backend.connect()
        goal = np.deg2rad([12.0, -12.0])
        for _ in range(60):
            measurement = backend.read()
            backend.write_goal(goal)
            time.sleep(0.005)
        backend.close()
    np.testing.assert_allclose(measurement.position_rad, goal, atol=np.deg2rad(1.5))


def test_a_child_emulator_starts_where_a_first_angle_below_zero_says(robot):
    """``--start-deg -12.5,3`` once read as an option of its own: the child refused."""
    with spawn_emulator(start_deg=(-12.5, 3.0)) as child:
        backend = DynamixelRobot(robot.actuator, child.device)
        backend.connect()
        measured = backend.read().position_rad
        backend.close()
    np.testing.assert_allclose(measured, np.deg2rad([-12.5, 3.0]), atol=np.deg2rad(0.1))


def test_a_vanished_device_is_a_communication_error_every_time(robot):
    with connected(robot) as (emulator, backend):
        emulator.close()  # as if the adapter were unplugged
        for _ in range(2):  # the port is not left busy ("Port is in use!") by a failure
            with pytest.raises(CommunicationError, match=r"^port: "):
                backend.write_goal(np.zeros(2))
            with pytest.raises(CommunicationError, match=r"^port: "):
                backend.read()
            with pytest.raises(CommunicationError, match=r"^port: "):
                backend.read_current(0.1)
        assert backend.describe()["communication_failures"] == {
            "connect": 0,
            "read": 2,
            "current read": 2,
            "write": 2,
        }
