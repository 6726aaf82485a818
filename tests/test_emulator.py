"""The emulated actuators, seen through the official SDK (dynamixel-sdk 4.1.0)."""

import contextlib
import time
from pathlib import Path

import numpy as np
import pytest
import serial
from dynamixel_sdk import GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler
from hypothesis import given
from hypothesis import strategies as st

from spm_opt.base.errors import InputError
from spm_opt.cli import main as cli_main
from spm_opt.execution.emulator import (
    CorruptReplies,
    DelayReplies,
    DropReplies,
    Emulator,
    Faults,
    Overload,
    RefusedWrites,
    StuckEncoder,
    parse_fault,
    parse_faults,
    spawn_emulator,
)
from spm_opt.execution.plant import PlantSettings, StateTrace
from spm_opt.execution.protocol import BROADCAST_ID, Instruction, PacketReader, build_instruction
from spm_opt.model.params import load_robot

pytestmark = pytest.mark.real_time

ROOT = Path(__file__).resolve().parents[1]
COMM_SUCCESS, COMM_RX_TIMEOUT, COMM_RX_CORRUPT = 0, -3001, -3002
GOAL_POSITION, PRESENT_POSITION, TORQUE_ENABLE, HARDWARE_ERROR = 596, 611, 562, 892
ALERT = 0x80


@pytest.fixture(scope="module")
def robot():
    return load_robot(ROOT / "problems" / "robots" / "prototype.toml")


class PatientPort(PortHandler):
    """The SDK's port, waiting ``patience_ms`` longer for a reply than its usual 34 ms: a
    loaded test machine can hold a reply up for tens of ms, which is not what these tests
    are about. Tests that expect a timeout use :func:`impatient`."""

    patience_ms = 1000.0

    def setPacketTimeout(self, packet_length):  # noqa: N802 (the SDK's name)
        super().setPacketTimeout(packet_length)
        self.packet_timeout += self.patience_ms


@contextlib.contextmanager
def impatient(port):
    """The SDK's own timeout, for transactions expected to time out."""
    port.patience_ms = 0.0
    try:
        yield
    finally:
        port.patience_ms = PatientPort.patience_ms


def connect(device):
    port = PatientPort(device)
    assert port.openPort() and port.setBaudRate(4_000_000)
    return port, PacketHandler(2.0)


COARSE = PlantSettings(step_s=0.004)
"""In-process emulators share the GIL with the SDK's busy polling: coarse plant steps keep
their share of it small, so that replies stay prompt."""


@pytest.fixture
def bus(robot):
    """An in-process emulator without faults, and an SDK port on it."""
    with Emulator(robot, plant_settings=COARSE) as emulator:
        port, ph = connect(emulator.device)
        yield emulator, port, ph
        port.closePort()


def signed(value, size=4):
    return int.from_bytes(value.to_bytes(size, "little"), "little", signed=True)


def word(value):
    return list(int(value).to_bytes(4, "little", signed=True))


def enable_and_start(port, ph, goal=(0, 0)):
    """Torque on for both, then one sync write of goal positions (starts the fault clock)."""
    for device_id in (1, 2):
        assert ph.write1ByteTxRx(port, device_id, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    sync_write(port, ph, goal)


def sync_write(port, ph, goal):
    writer = GroupSyncWrite(port, ph, GOAL_POSITION, 4)
    for device_id, pulses in zip((1, 2), goal, strict=True):
        writer.addParam(device_id, word(pulses))
    assert writer.txPacket() == COMM_SUCCESS


def sync_read_positions(port, ph):
    reader = GroupSyncRead(port, ph, PRESENT_POSITION, 12)
    reader.addParam(1)
    reader.addParam(2)
    result = reader.txRxPacket()
    if result != COMM_SUCCESS:
        return result, None
    return result, [signed(reader.getData(i, PRESENT_POSITION, 4)) for i in (1, 2)]


def exchange(port, packet, replies, timeout_s=1.0):
    """Send raw bytes; collect up to ``replies`` status packets."""
    port.clearPort()
    port.writePort(packet)
    reader, packets = PacketReader(), []
    deadline = time.monotonic() + timeout_s
    while len(packets) < replies and time.monotonic() < deadline:
        packets += reader.feed(port.readPort(64))
    return packets


# --------------------------------------------------------------------- instructions
def test_ping_both_ids(bus):
    _, port, ph = bus
    assert ph.ping(port, 1) == (38152, COMM_SUCCESS, 0)
    assert ph.ping(port, 2) == (38152, COMM_SUCCESS, 0)
    with impatient(port):
        assert ph.ping(port, 3)[1] == COMM_RX_TIMEOUT


def test_broadcast_ping_is_answered_by_both_in_id_order(bus):
    _, port, _ = bus
    packets = exchange(port, build_instruction(BROADCAST_ID, Instruction.PING), 2)
    assert [(p.id, p.error, p.data) for p in packets] == [
        (1, 0, bytes.fromhex("08 95 00")),
        (2, 0, bytes.fromhex("08 95 00")),
    ]


def test_broadcast_read_gets_no_reply(bus):
    _, port, _ = bus
    read = build_instruction(BROADCAST_ID, Instruction.READ, bytes.fromhex("00 00 02 00"))
    assert exchange(port, read, 1, timeout_s=0.05) == []


def test_position_moves_toward_the_sync_written_goal(bus):
    emulator, port, ph = bus
    goal = (20_000, -15_000)  # about 20° and -15°
    enable_and_start(port, ph, goal)
    assert ph.read1ByteTxRx(port, 1, TORQUE_ENABLE) == (1, COMM_SUCCESS, 0)
    trace = []
    start = time.monotonic()
    nearly_there = 0.05 * np.abs(goal)
    while time.monotonic() - start < 10.0:  # ends on arrival; the deadline only on a failure
        sync_write(port, ph, goal)
        result, positions = sync_read_positions(port, ph)
        assert result == COMM_SUCCESS
        trace.append(positions)
        if np.all(np.abs(np.subtract(positions, goal)) < nearly_there):
            break
    trace = np.array(trace)
    assert len(trace) > 5  # a motion, not one jump
    error = np.abs(trace - goal)
    assert np.all(error[-1] < nearly_there)
    assert np.all(np.diff(error, axis=0) <= 0.01 * np.abs(goal))  # never moving away
    assert signed(ph.read4ByteTxRx(port, 2, GOAL_POSITION)[0]) == -15_000
    np.testing.assert_allclose(emulator.plant.goal_position_rad, [0.3477, -0.2608], atol=1e-3)


def test_eeprom_write_with_torque_on_is_an_access_error(bus):
    emulator, port, ph = bus
    assert ph.write4ByteTxRx(port, 1, 32, 4000) == (COMM_SUCCESS, 0)  # torque off: allowed
    assert emulator.plant.velocity_limit_rad_s[0] == pytest.approx(4000 * 0.00199234 * np.pi / 30)
    assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, 32, 2000) == (COMM_SUCCESS, 7)
    assert ph.read4ByteTxRx(port, 1, 32) == (4000, COMM_SUCCESS, 0)


def test_bad_instruction_gets_the_instruction_error(bus):
    _, port, ph = bus
    packet = [0] * 10
    packet[4], packet[5], packet[7] = 1, 3, 0x7F  # id 1, LEN 3, instruction 0x7F
    _, result, error = ph.txRxPacket(port, packet)
    assert (result, error) == (COMM_SUCCESS, 2)


def test_bad_crc_gets_the_crc_error(bus):
    _, port, _ = bus
    ping = bytearray(build_instruction(2, Instruction.PING))
    ping[-1] ^= 0x55
    (reply,) = exchange(port, bytes(ping), 1)
    assert (reply.id, reply.error) == (2, 3)


@pytest.mark.parametrize(
    ("address", "value", "size", "error"),
    [
        (GOAL_POSITION, 200_000, 4, 4),  # beyond the Max Position Limit 180,692
        (GOAL_POSITION, 1_000, 2, 5),  # half of a 4-byte item
        (PRESENT_POSITION, 0, 4, 7),  # read-only
        (619, 0, 2, 7),  # unlisted bytes
        (11, 2, 1, 4),  # operating mode 2 does not exist
    ],
)
def test_write_errors(bus, address, value, size, error):
    _, port, ph = bus
    data = list(value.to_bytes(size, "little", signed=True))
    assert ph.writeTxRx(port, 1, address, size, data) == (COMM_SUCCESS, error)


def test_reads_serve_any_range_with_unlisted_bytes_as_zero(bus):
    _, port, ph = bus
    data, result, error = ph.readTxRx(port, 2, 0, 12)
    assert (result, error) == (COMM_SUCCESS, 0)
    assert data[:2] == [0x08, 0x95] and data[7] == 2 and data[2:6] == [0, 0, 0, 0]
    assert ph.readTxRx(port, 2, 890, 10)[1:] == (COMM_SUCCESS, 7)  # past the table


def test_sdk_unstuffed_goal_minus_131073_is_understood(bus):
    emulator, port, ph = bus
    sent = []
    write_port = port.writePort
    port.writePort = lambda packet: sent.append(bytes(packet)) or write_port(packet)
    assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, -131073) == (COMM_SUCCESS, 0)
    # the SDK's defect: FF FF FD in the data, not stuffed, LEN of the raw params
    assert len(sent[0]) == 16
    assert sent[0][:14] == bytes.fromhex("FF FF FD 00 01 09 00 03 54 02 FF FF FD FF")
    value, result, error = ph.read4ByteTxRx(port, 1, GOAL_POSITION)
    assert (signed(value), result, error) == (-131073, COMM_SUCCESS, 0)
    assert emulator.plant.goal_position_rad[0] == pytest.approx(-131073 * 2 * np.pi / 361_384)


def test_sdk_unstuffed_fd_fd_is_read_as_whole_items(bus):
    # 0xFDFDFFFF goes out as FF FF FD FD: stripping the last FD (the standard reading)
    # would leave 3 bytes of a 4-byte item, so the emulator takes the bytes as they came
    _, port, ph = bus
    homing_offset = 13
    value = signed(0xFDFDFFFF)
    assert ph.write4ByteTxRx(port, 1, homing_offset, value) == (COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 1, homing_offset) == (0xFDFDFFFF, COMM_SUCCESS, 0)


def test_stuffed_write_from_a_compliant_sender(bus):
    emulator, port, _ = bus
    params = GOAL_POSITION.to_bytes(2, "little") + (-131073).to_bytes(4, "little", signed=True)
    packet = build_instruction(2, Instruction.WRITE, params)
    assert bytes.fromhex("FF FF FD FD FF") in packet  # stuffed
    (reply,) = exchange(port, packet, 1)
    assert (reply.id, reply.error) == (2, 0)
    assert emulator.plant.goal_position_rad[1] == pytest.approx(-131073 * 2 * np.pi / 361_384)


def test_reboot_turns_torque_off(bus):
    _, port, ph = bus
    enable_and_start(port, ph)
    assert ph.reboot(port, 1) == (COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 1, TORQUE_ENABLE) == (0, COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 2, TORQUE_ENABLE) == (1, COMM_SUCCESS, 0)


# --------------------------------------------------------------------------- faults
@pytest.fixture
def faulty(robot):
    """Build an emulator with faults and connect; closed at the end of the test."""
    opened = []

    def make(faults):
        emulator = Emulator(robot, faults=faults, plant_settings=COARSE).__enter__()
        port, ph = connect(emulator.device)
        opened.append((emulator, port))
        return emulator, port, ph

    yield make
    for emulator, port in opened:
        port.closePort()
        emulator.close()


def test_no_fault_before_the_first_goal_write(faulty):
    _, port, ph = faulty(Faults(drop=DropReplies(at=0.0)))
    assert ph.ping(port, 1)[1] == COMM_SUCCESS
    enable_and_start(port, ph)
    with impatient(port):
        assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT


def test_dropped_replies_time_out(faulty):
    _, port, ph = faulty(Faults(drop=DropReplies(at=0.0, count=2)))
    enable_and_start(port, ph)
    with impatient(port):
        assert sync_read_positions(port, ph)[0] == COMM_RX_TIMEOUT  # both replies dropped
    assert ph.ping(port, 1)[1] == COMM_SUCCESS


def test_corrupt_crc_replies(faulty):
    _, port, ph = faulty(Faults(crc=CorruptReplies(at=0.0, count=1)))
    enable_and_start(port, ph)
    assert ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[1] == COMM_RX_CORRUPT
    assert ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[1] == COMM_SUCCESS


def test_overload_sets_hardware_error_and_alert(faulty):
    emulator, port, ph = faulty(Faults(overload=(Overload(id=1, at=0.2),)))
    enable_and_start(port, ph)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)
    time.sleep(0.25)
    status, result, error = ph.read1ByteTxRx(port, 1, HARDWARE_ERROR)
    assert (status, result, error) == (1 << 5, COMM_SUCCESS, ALERT)
    assert ph.read1ByteTxRx(port, 1, TORQUE_ENABLE) == (0, COMM_SUCCESS, ALERT)
    assert ph.ping(port, 1) == (38152, COMM_SUCCESS, ALERT)
    assert ph.read1ByteTxRx(port, 2, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, ALERT)
    assert not emulator.plant.torque_enabled[0]
    assert ph.reboot(port, 1) == (COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR) == (0, COMM_SUCCESS, 0)


def test_stuck_encoder_freezes_the_position(faulty):
    _, port, ph = faulty(Faults(stuck=(StuckEncoder(id=2, at=0.0),)))
    enable_and_start(port, ph)
    readings = []
    for k in range(1, 101):
        sync_write(port, ph, (100 * k, 100 * k))
        readings.append(sync_read_positions(port, ph)[1])
        time.sleep(0.002)
    readings = np.array(readings)
    assert readings[-1, 0] > 3000  # θ1 follows its goal
    assert np.all(readings[:, 1] == readings[0, 1])  # θ2's encoder reports one value


def test_delayed_replies_arrive_late(faulty):
    _, port, ph = faulty(Faults(delay=DelayReplies(seconds=0.1, at=0.0, count=2)))
    enable_and_start(port, ph)
    latencies = []
    for _ in range(4):
        start = time.perf_counter()
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        latencies.append(time.perf_counter() - start)
    assert min(latencies[:2]) >= 0.1
    assert max(latencies[2:]) < 0.1


def test_refused_writes_fail_at_the_port_then_recover(faulty, robot):
    """For 0.3 s the line takes no byte: a sync write (which gets no reply, so only the port
    can fail it) times out in pyserial, and its goal never reaches the plant."""
    emulator, port, ph = faulty(Faults(write=RefusedWrites(at=0.0, seconds=0.3)))
    port.ser.write_timeout = 0.02
    enable_and_start(port, ph)  # starts the faults' clock
    time.sleep(0.02)
    writer = GroupSyncWrite(port, ph, GOAL_POSITION, 4)
    for device_id in (1, 2):
        writer.addParam(device_id, word(1000))
    with pytest.raises(serial.SerialTimeoutException):
        writer.txPacket()
    port.is_using = False  # the SDK leaves its port busy when pyserial raises
    time.sleep(0.02)
    assert np.all(emulator.plant.goal_position_rad == 0.0)
    time.sleep(0.3)
    sync_write(port, ph, (1000, 1000))
    time.sleep(0.02)
    held = robot.actuator.pulses(emulator.plant.goal_position_rad)
    np.testing.assert_array_equal(held, [1000, 1000])


def test_the_emulator_records_the_plants_true_state(robot):
    trace = StateTrace()
    with Emulator(robot, plant_settings=COARSE, trace=trace) as emulator:
        port, ph = connect(emulator.device)
        begin = time.monotonic()
        enable_and_start(port, ph, (2000, -1000))
        deadline, positions, previous = time.monotonic() + 60.0, None, None
        while positions is None or positions != previous:  # read at rest: later when busy
            assert time.monotonic() < deadline, "the positions read never settled"
            previous = positions
            time.sleep(0.1)
            _, positions = sync_read_positions(port, ph)
        end = time.monotonic()
        port.closePort()
    recorded = trace.arrays()
    assert begin <= recorded["time_s"][0] and recorded["time_s"][-1] <= end + 0.1
    assert np.all(np.diff(recorded["time_s"]) > 0)
    pulses = robot.actuator.pulses(recorded["position_rad"][-1])
    np.testing.assert_allclose(pulses, positions, atol=1)  # the plant at rest: same pulse
    np.testing.assert_allclose(
        robot.actuator.pulses(recorded["goal_rad"][-1]), [2000, -1000], atol=0
    )
    assert np.max(np.abs(recorded["velocity_rad_s"][-1])) < 1e-3


def test_faults_must_name_emulated_ids(robot):
    with pytest.raises(InputError, match="id 5"):
        Emulator(robot, faults=Faults(overload=(Overload(id=5),)))


# ---------------------------------------------------------------------- fault text
def test_parse_fault_examples():
    assert parse_fault("overload:id=1,at=3.0") == Overload(id=1, at=3.0)
    assert parse_fault("drop:at=2.0,count=50") == DropReplies(at=2.0, count=50)
    assert parse_fault("drop:at=2.0") == DropReplies(at=2.0)
    assert parse_fault("crc:at=1.0,count=3") == CorruptReplies(at=1.0, count=3)
    assert parse_fault(" delay: at=1.0, seconds=0.05, count=5") == DelayReplies(0.05, 1.0, 5)
    assert parse_fault("stuck:id=2,at=1.5") == StuckEncoder(id=2, at=1.5)
    assert parse_fault("write:at=1,seconds=0.5") == RefusedWrites(seconds=0.5, at=1.0)
    faults = parse_faults(["drop:at=2", "stuck:id=2,at=1.5", "overload:id=1,at=3"])
    assert faults == Faults(
        drop=DropReplies(at=2.0),
        overload=(Overload(id=1, at=3.0),),
        stuck=(StuckEncoder(id=2, at=1.5),),
    )


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("explode:at=1", "unknown kind 'explode'"),
        ("drop:when=1", "field one of at, count"),
        ("drop:at", "field one of at, count"),
        ("drop:at=soon", "at must be a number"),
        ("drop:at=-1", "at must be a time >= 0"),
        ("crc:count=0", "count must be an integer >= 1"),
        ("crc:count=1.5", "count must be an integer"),
        ("delay:at=1", "'seconds' is required"),
        ("delay:seconds=0", "seconds must be > 0"),
        ("write:at=1", "'seconds' is required"),
        ("write:seconds=inf", "seconds must be > 0"),
        ("overload:at=1", "'id' is required"),
        ("stuck:id=300", "id must be an integer 0-252"),
        ("drop:at=1,at=2", "given twice"),
    ],
)
def test_parse_fault_rejects(text, match):
    with pytest.raises(InputError, match=match):
        parse_fault(text)


def test_parse_faults_rejects_a_repeated_reply_fault():
    with pytest.raises(InputError, match="drop: given more than once"):
        parse_faults(["drop:at=1", "drop:at=2"])


times = st.floats(0.0, 1e4, allow_nan=False)
counts = st.none() | st.integers(1, 10_000)
faults = st.one_of(
    st.builds(DropReplies, times, counts),
    st.builds(CorruptReplies, times, counts),
    st.builds(DelayReplies, st.floats(1e-6, 10.0), times, counts),
    st.builds(RefusedWrites, st.floats(1e-6, 10.0), times),
    st.builds(Overload, st.integers(0, 252), times),
    st.builds(StuckEncoder, st.integers(0, 252), times),
)


@given(faults)
def test_fault_text_round_trip(fault):
    assert parse_fault(fault.spec()) == fault


# --------------------------------------------------------------- the child process
def test_the_command_line_rejects_bad_input(capsys):
    assert cli_main(["emulate", "--ids", "1"]) == 2
    assert "--ids" in capsys.readouterr().err
    assert cli_main(["emulate", "--ids", "3,3"]) == 2
    assert "distinct" in capsys.readouterr().err
    assert cli_main(["emulate", "--fault", "drop:at=x"]) == 2


def test_spawned_emulator_serves_the_sdk(tmp_path):
    faults = Faults(overload=(Overload(id=2, at=0.3),))
    trace_path = tmp_path / "plant.npz"
    with spawn_emulator(start_deg=(10.0, -5.0), faults=faults, trace_path=trace_path) as child:
        port, ph = connect(child.device)
        assert ph.ping(port, 1) == (38152, COMM_SUCCESS, 0)
        assert ph.ping(port, 2) == (38152, COMM_SUCCESS, 0)
        _, start = sync_read_positions(port, ph)
        assert start == pytest.approx([361_384 / 36, -361_384 / 72], abs=1)  # 10°, -5°
        goal = (start[0] + 5_000, start[1])
        enable_and_start(port, ph, goal)
        begin = time.monotonic()
        while time.monotonic() - begin < 0.2:
            sync_write(port, ph, goal)
            result, positions = sync_read_positions(port, ph)
            assert result == COMM_SUCCESS
        assert abs(positions[0] - goal[0]) < 500  # most of the way in 0.2 s
        time.sleep(0.15)
        assert ph.read1ByteTxRx(port, 2, HARDWARE_ERROR) == (1 << 5, COMM_SUCCESS, ALERT)
        port.closePort()
        process = child.process
    assert process.returncode == 0
    # the child saved the plant's true state when it ended: the goal, and θ2 stopped by the
    # overload (torque off: held by its gear)
    trace = StateTrace.load(trace_path)
    assert trace["time_s"][-1] - trace["time_s"][0] >= 0.35
    np.testing.assert_allclose(trace["goal_rad"][-1, 0], goal[0] * 2 * np.pi / 361_384)
    assert trace["velocity_rad_s"][-1, 1] == 0.0
