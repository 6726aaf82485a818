"""Two Dynamixel PRO actuators through the official ``dynamixel-sdk`` (Protocol 2.0).

Facts from ``docs/dynamixel.md``. One control cycle is two transactions:

- ``read``: one sync read of 12 bytes at 611 (Present Position 4, Present Velocity 4, two
  unlisted bytes, Present Current 2) for both ids. The instruction goes out through the
  SDK's ``GroupSyncRead``; the two status packets are received with the packet handler's
  ``readRx``, which, unlike ``GroupSyncRead.rxPacket``, keeps each device's error byte. Its
  alert bit (bit 7) says that the device has a Hardware Error Status; only then is 892 read
  (one extra transaction per actuator in error), so a healthy cycle costs nothing extra and
  an overload shows in the very next ``read``.
- ``write_goal``: one ``GroupSyncWrite`` of 4 bytes at 596, which gets no reply.
- ``read_current``: one sync read of 2 bytes at 621 (Present Current), which the control
  loop makes while a goal is held (``ExecutionSettings.current_reads_per_cycle``); no retry: a
  failed one is counted and left out of the cycle's mean.

Replies that are not the reply. Protocol 2.0's status packets carry no sequence number, and
the SDK clears the port only before it sends: a reply that comes after its request timed
out lands in the next request's wait, and the SDK takes any status packet of the right id
for the answer (a late 12-byte reading once passed for the next reading, 37 ms stale, and
for a Hardware Error Status byte of 137). So every reply is received here with the SDK's
``rxPacket`` and checked against its request: id, instruction (status) and length; a
packet that fails is a stale reply, counted and skipped while the request's timeout runs.
A late reply to the same request would still pass those checks, so after a read fails
the next one asks for another length (:data:`READ_LENGTHS`), and late replies to the
failed one are told apart by theirs.

What a failed write is. A broadcast sync write gets no status packet, so the bus cannot
say that one was lost or refused: the SDK's ``txPacket`` returns ``COMM_SUCCESS`` once the
port (pyserial, then the kernel's tty buffer) has taken the bytes. A write therefore fails,
honestly, only at the port: the SDK reports a result other than success (port busy, a
short write), or pyserial raises (the device is gone: EIO; or the port took no bytes
within :data:`WRITE_TIMEOUT_S`: a stalled adapter, flow control holding the line). Each
is a :class:`CommunicationError` and is counted. A goal lost on the wire after the port took
it is not seen here; the next reads (position, following error) are what show it. The
converse also happens: pyserial, after writing, waits for room for more, so a line that
stalls just after a packet left fails a write whose goal arrived. On a real USB adapter
the kernel buffers some kilobytes, so a stall of the adapter shows as a write failure
only once that buffer is full; the read's missing replies show it at once.

The SDK opens its port with timeout 0 and polls it in a busy loop, which takes a CPU core
(and the GIL) from everything else while it waits; the backend gives the port a 1 ms read
timeout instead, so that the SDK's reads block until the bytes they ask for arrive. Its
writes get a write timeout (pyserial's default waits for ever, which would stall the
control loop on a stalled port).

The SDK 4.1.0 discards the result of its own byte stuffing, so a packet whose instruction
or parameters contain ``FF FF FD`` would go out unstuffed. :func:`stuffing_safe_goals`
nudges such a goal by the fewest pulses (1 for every goal inside the position limits; the
only such value is −131,073, bytes ``FF FF FD FF``), and the backend counts and logs it.
"""

from __future__ import annotations

import errno
import itertools
import logging
import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from spm_opt.base.errors import DeviceError, InputError, require
from spm_opt.base.input_limits import excerpt
from spm_opt.execution.backend import (
    CommunicationError,
    Measurement,
    MonotonicClock,
    hardware_error_names,
)
from spm_opt.model.actuator import Actuator

logger = logging.getLogger(__name__)

try:
    import termios

    PORT_ERRORS: tuple[type[Exception], ...] = (OSError, termios.error)
except ImportError:  # not POSIX
    PORT_ERRORS = (OSError,)
"""What pyserial raises when the device goes away (termios errors are not OSErrors)."""

# The client's own copy of the model number, the control table's addresses and the
# protocol's constants, typed from the datasheet (docs/dynamixel.md) apart from the
# emulator's control table and spm_opt.execution.protocol on purpose: the tests drive this
# client through the official SDK against the emulator, and an address shared by both would
# be wrong on both sides at once without a test noticing. tests/test_dynamixel.py compares
# the two copies.
MODEL_NUMBERS: dict[str, int] = {"L54-50-S500-R": 38152}
"""Model Number (control table address 0) of each actuator model, by ``Actuator.model``."""

BAUD_RATES = (9600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000)
"""Baud rates, bit/s, that both the actuator (address 8) and the SDK's port handler accept."""

DEFAULT_BAUD = 1_000_000
"""The common Dynamixel rate: a cycle's 86 bytes take 0.9 ms, a tenth of the 100 Hz
period, and RS-485 at 1 Mbit/s tolerates longer cables and more adapters than 4 Mbit/s."""

MAX_ID = 252
"""Largest device id (0xFD, 0xFE and 0xFF are reserved), so an id byte is never FF or FD."""

ADDR_OPERATING_MODE = 11
ADDR_MAX_POSITION_LIMIT = 36
ADDR_MIN_POSITION_LIMIT = 40
ADDR_TORQUE_ENABLE = 562
ADDR_GOAL_POSITION = 596
ADDR_PRESENT_POSITION = 611
ADDR_PRESENT_CURRENT = 621
ADDR_HARDWARE_ERROR = 892
ITEM_NAMES = {
    ADDR_OPERATING_MODE: "Operating Mode",
    ADDR_MAX_POSITION_LIMIT: "Max Position Limit",
    ADDR_MIN_POSITION_LIMIT: "Min Position Limit",
    ADDR_TORQUE_ENABLE: "Torque Enable",
    ADDR_PRESENT_POSITION: "Present Position",
    ADDR_PRESENT_CURRENT: "Present Current",
    ADDR_HARDWARE_ERROR: "Hardware Error Status",
}
READ_LENGTHS = (12, 14, 15)
"""Lengths of the sync read at 611, bytes: Present Position (611, 4), Present Velocity (615,
4), 619–620 unlisted and Present Current (621, 2); then Present Input Voltage (623, 2) and
Present Temperature (625, 1), read only to make the reply's length differ. Each failed
read moves on to the next length, so that a late reply to it cannot pass for the reply to
the next read (a reply must be later than two failed reads' timeouts, about 70 ms, to be
taken for one of the same length)."""
POSITION_MODE = 3
OPERATING_MODES = {0: "torque", 1: "velocity", 3: "position", 4: "extended position"}

READ_BLOCK_S = 0.001
"""Longest a read of the port blocks for bytes that do not come, s (the SDK asks for no
more bytes than the packet it is reading has left, so a read normally returns at once)."""

WRITE_TIMEOUT_S = 0.02
"""Longest a write waits for the port to take its bytes, s, before it fails. A healthy
port takes a packet at once (into the kernel's buffer), but pyserial also fails a write
whose bytes went out when the process was descheduled for longer than this between its
start and its check; on 2 cores under 3 busy processes, 5 ms failed 17 of 3000 writes that
went out, 20 ms none. Like the SDK's 34 ms reply timeout, it bounds a cycle on a dead line."""

INST_SYNC_WRITE = 0x83
INST_STATUS = 0x55
BROADCAST_ID = 0xFE
ALERT_BIT = 0x80
"""Bit 7 of a status packet's error byte: the device has a Hardware Error Status."""
HEADER_PATTERN = b"\xff\xff\xfd"


def sync_write_body(ids: Sequence[int], goals: Sequence[int]) -> bytes:
    """The bytes of the goal-position sync write from the id (FE) to the last parameter.

    These are the bytes the SDK would byte-stuff (its scan covers windows from LEN on;
    the header and the CRC are outside stuffing by the protocol's definition).
    """
    length = len(ids) * 5 + 7  # parameters + instruction + CRC
    body = bytearray([BROADCAST_ID, length & 0xFF, length >> 8, INST_SYNC_WRITE])
    body += ADDR_GOAL_POSITION.to_bytes(2, "little") + (4).to_bytes(2, "little")
    for dxl_id, goal in zip(ids, goals, strict=True):
        body.append(dxl_id)
        body += int(goal).to_bytes(4, "little", signed=True)
    return bytes(body)


def stuffing_safe_goals(
    ids: Sequence[int], goals: Sequence[int], previous: Sequence[int] | None = None
) -> list[int]:
    """Goals, pulses, changed by the fewest pulses so that the sync write needs no stuffing.

    Goal k's four bytes take part in the windows inside them, in those that start in the
    two bytes before them (goal k − 1's last byte, or the data length's high byte, and
    goal k's id) and in those that end in the next id byte. Goals are fixed in order, each
    checked with every window that ends at or before the next id (windows reaching into
    goal k + 1 are checked with it). Equal nudges go toward the previous goal (toward +1
    without one). Ids are at most 252, so only a goal's own bytes can form ``FF FF FD``;
    inside the position limits only −131,073 (``FF FF FD FF``) does, and 1 pulse fixes it.

    Parameters
    ----------
    ids : sequence of int, 0–252
    goals : sequence of int, pulses (signed 32-bit)
    previous : sequence of int, pulses, optional
        The goals sent last time.

    Returns
    -------
    list of int, pulses
    """
    safe = [int(goal) for goal in goals]
    for k, goal in enumerate(safe):
        toward = -1 if previous is not None and previous[k] < goal else 1
        for candidate in _nearest(goal, toward):
            safe[k] = candidate
            if HEADER_PATTERN not in sync_write_body(ids, safe)[7 + 5 * k : 14 + 5 * k]:
                break
    return safe


def _nearest(value: int, toward: int) -> Iterator[int]:
    """value, value + toward, value − toward, value + 2 toward, …"""
    yield value
    for step in itertools.count(1):
        yield value + step * toward
        yield value - step * toward


class DynamixelRobot:
    """Two Dynamixel PRO actuators on one serial bus, through ``dynamixel-sdk``.

    Parameters
    ----------
    actuator : Actuator
        The actuators' model (units; its model number is checked at ``connect``).
    port : str
        Serial device, e.g. ``/dev/ttyUSB0`` (a pseudo-terminal works).
    baud : int, bit/s
        One of :data:`BAUD_RATES`; it must equal the actuators' Baud Rate (address 8).
    ids : (int, int)
        Device ids of the actuators driving θ1 and θ2, distinct, 0–252.
    retries : int
        Extra attempts of a failed read transaction before :class:`CommunicationError`
        (a sync write gets no reply, so it is never retried). Every failure is counted.
    timeout_s : float or None, s
        Time allowed for both replies of a ``read``; None keeps the SDK's estimate (the
        bytes' time + 34 ms, written for a 16 ms USB latency timer).
    write_timeout_s : float, s
        Time allowed for the port to take a packet (see :data:`WRITE_TIMEOUT_S`).

    Attributes
    ----------
    clock : MonotonicClock
    position_limits : list of (int, int), pulses
        Min and Max Position Limit of each actuator: ±half a turn until ``connect`` reads
        them (the device silently drops a sync-written goal beyond them).
    nudge_count : int
        Goals changed by one or more pulses to avoid the SDK's stuffing defect.
    stale_replies : int
        Status packets received that did not answer the request in wait (another id or
        length): late replies to a request that timed out, skipped.
    """

    def __init__(
        self,
        actuator: Actuator,
        port: str,
        baud: int = DEFAULT_BAUD,
        ids: tuple[int, int] = (1, 2),
        retries: int = 0,
        timeout_s: float | None = None,
        write_timeout_s: float = WRITE_TIMEOUT_S,
    ) -> None:
        if actuator.model not in MODEL_NUMBERS:
            raise InputError(
                f"actuator.model: {actuator.model!r} has no known model number; "
                f"expected one of {', '.join(MODEL_NUMBERS)}"
            )
        if baud not in BAUD_RATES:
            raise InputError(
                f"baud: {excerpt(baud)} is not supported; expected one of "
                f"{', '.join(str(rate) for rate in BAUD_RATES)}"
            )
        if (
            len(ids) != 2
            or any(not isinstance(i, int | np.integer) or not 0 <= i <= MAX_ID for i in ids)
            or ids[0] == ids[1]
        ):
            raise InputError(f"ids: {excerpt(ids)}; expected two distinct integers in 0–{MAX_ID}")
        if not isinstance(retries, int) or retries < 0:
            raise InputError(f"retries: {excerpt(retries)}; expected an integer ≥ 0")
        if timeout_s is not None and not (math.isfinite(timeout_s) and timeout_s > 0.0):
            raise InputError(
                f"timeout_s: {excerpt(timeout_s)}; expected a positive number of seconds"
            )
        if not (isinstance(write_timeout_s, int | float) and 0.0 < write_timeout_s <= 1.0):
            raise InputError(
                f"write_timeout_s: {excerpt(write_timeout_s)}; expected a number of seconds "
                "in (0, 1]"
            )
        self.actuator = actuator
        self.port = port
        self.baud = baud
        self.ids = (int(ids[0]), int(ids[1]))
        self.retries = retries
        self.timeout_s = timeout_s
        self.write_timeout_s = float(write_timeout_s)
        self.clock = MonotonicClock()
        self.nudge_count = 0
        self.stale_replies = 0
        half_turn = actuator.pulses_per_rev // 2
        self.position_limits: list[tuple[int, int]] = [(-half_turn, half_turn)] * 2
        self.model_numbers: list[int | None] = [None, None]
        self.firmware_versions: list[int | None] = [None, None]
        self.failures = {"connect": 0, "read": 0, "current read": 0, "write": 0}
        self._sdk: Any = None
        self._port: Any = None
        self._packets: Any = None
        self._sync_reads: list[Any] = []
        self._read_turn = 0
        self._sync_write: Any = None
        self._last_goal: list[int] | None = None

    # ------------------------------------------------------------------ lifecycle
    def connect(self) -> None:
        """Open the port, check both actuators and enable torque in position mode.

        Each actuator must answer a ping with the actuator model's number, be in position
        mode (3; this backend does not change EEPROM settings: a mode change would also
        re-base Present Position) and have no Hardware Error Status; its position limits
        are read. If its torque is off, the goal is first set to the present position, so
        that enabling torque holds the arm where it is.

        Raises
        ------
        InputError
            Port that does not exist, wrong model number or operating mode.
        CommunicationError
            A transaction failed (no reply, corrupt reply, refused by the device).
        DeviceError
            An actuator reports a hardware error (it needs a reboot, see :meth:`reboot`).
        """
        self._open()
        try:
            for k, dxl_id in enumerate(self.ids):
                self._check_device(k, dxl_id)
            torque = [self._read_value(dxl_id, ADDR_TORQUE_ENABLE, 1) for dxl_id in self.ids]
            if not all(torque):
                present = [
                    self._read_value(dxl_id, ADDR_PRESENT_POSITION, 4, signed=True)
                    for dxl_id in self.ids
                ]
                self._send_goals(present)
            for dxl_id, on in zip(self.ids, torque, strict=True):
                if not on:
                    self._transaction(
                        "write Torque Enable",
                        dxl_id,
                        lambda i=dxl_id: self._packets.writeTxOnly(
                            self._port, i, ADDR_TORQUE_ENABLE, 1, [1]
                        ),
                        reply_length=0,
                    )
        except BaseException:
            self.close()
            raise
        logger.info(
            "connected to ids %s on %s at %d baud (models %s, firmware %s)",
            self.ids,
            self.port,
            self.baud,
            self.model_numbers,
            self.firmware_versions,
        )

    def close(self) -> None:
        """Close the port; torque stays enabled, so the actuators hold their last goal."""
        if self._port is not None:
            port, self._port = self._port, None
            port.closePort()

    def reboot(self, dxl_id: int) -> None:
        """Reboot one actuator: clears its Hardware Error Status; its torque comes back off.

        Opens the port if needed; call :meth:`connect` afterwards to run again.
        """
        if dxl_id not in self.ids:
            raise InputError(f"dxl_id: {excerpt(dxl_id)} is not one of this robot's ids {self.ids}")
        if self._port is None:
            self._open()
        self._transaction("reboot", dxl_id, self._send_bare(dxl_id, "INST_REBOOT"), 0)

    # --------------------------------------------------------------------- cycle
    def read(self) -> Measurement:
        """Both actuators' present position, velocity and current, and hardware errors.

        Returns
        -------
        Measurement
            Position rad, velocity rad/s, current A (signed), Hardware Error Status.

        Raises
        ------
        CommunicationError
            Every attempt of the sync read failed.
        """
        attempt = 0
        while True:
            try:
                return self._read_once()
            except CommunicationError as exc:
                self.failures["read"] += 1
                if attempt == self.retries:
                    raise
                attempt += 1
                logger.debug("read failed, attempt %d of %d: %s", attempt, self.retries + 1, exc)

    def read_current(self, timeout_s: float) -> np.ndarray:
        """Both actuators' Present Current, A (signed): one sync read of 2 bytes at 621,
        its replies awaited at most ``timeout_s`` (s; and at most the backend's timeout).

        Raises
        ------
        CommunicationError
            The sync read failed (counted; not retried).
        """
        if self._port is None:
            raise CommunicationError("read_current: the port is not open; call connect() first")
        if self.timeout_s is not None:
            timeout_s = min(timeout_s, self.timeout_s)
        try:
            raw, _ = self._sync_replies(self._current_read, ADDR_PRESENT_CURRENT, 2, timeout_s)
        except CommunicationError:
            self.failures["current read"] += 1
            raise
        return self.actuator.current([int.from_bytes(b, "little", signed=True) for b in raw])

    def write_goal(self, position_rad: np.ndarray) -> None:
        """Send both goal positions in one sync write.

        Parameters
        ----------
        position_rad : ndarray, shape (2,), rad
            Within the actuators' position limits (by default ±π rad, ±180,692 pulse); a
            goal whose bytes would need stuffing is nudged by a pulse (see
            :func:`stuffing_safe_goals`).

        Raises
        ------
        InputError
            A goal that is not finite or is beyond the position limits.
        CommunicationError
            The port did not take the packet: an SDK result other than success, a port
            error, or no room within ``write_timeout_s`` (see the module's docstring: a
            sync write gets no reply, so a packet the port took counts as sent).
        """
        position = np.asarray(position_rad, dtype=float)
        if position.shape != (2,) or not np.all(np.isfinite(position)):
            raise InputError(
                f"position_rad: {position.tolist()!r}; expected two finite angles in rad"
            )
        pulses = [int(p) for p in self.actuator.pulses(position)]
        for dxl_id, angle, goal, (low, high) in zip(
            self.ids, position, pulses, self.position_limits, strict=True
        ):
            if not low <= goal <= high:
                raise InputError(
                    f"position_rad: {angle:g} rad ({goal} pulse) for id {dxl_id}; expected "
                    f"within its position limits {low}…{high} pulse"
                )
        self._send_goals(pulses)

    def describe(self) -> dict[str, Any]:
        """Plain data for the log's header: device, settings and counters."""
        return {
            "backend": "dynamixel",
            "port": self.port,
            "baud": self.baud,
            "ids": list(self.ids),
            "position_limits_pulses": [list(limits) for limits in self.position_limits],
            "actuator": self.actuator.model,
            "model_numbers": list(self.model_numbers),
            "firmware_versions": list(self.firmware_versions),
            "retries": self.retries,
            "timeout_s": self.timeout_s,
            "write_timeout_s": self.write_timeout_s,
            "nudge_count": self.nudge_count,
            "stale_replies": self.stale_replies,
            "communication_failures": dict(self.failures),
        }

    # ------------------------------------------------------------------ internals
    def _open(self) -> None:
        serial = require("serial", "the Dynamixel backend")
        sdk = require("dynamixel_sdk", "the Dynamixel backend")

        self.close()
        port = sdk.PortHandler(self.port)
        try:
            port.setBaudRate(self.baud)  # opens the port at this rate (openPort() opens at 1M)
        except serial.SerialException as exc:
            if exc.errno == errno.ENOENT:
                raise InputError(
                    f"port: {self.port!r} does not exist; expected a serial device such as "
                    "/dev/ttyUSB0"
                ) from exc
            raise CommunicationError(f"port: cannot open {self.port!r}: {exc}") from exc
        # the SDK polls a port opened with timeout 0 in a busy loop; a short blocking read
        # waits for the bytes it asks for without spinning (and without holding the GIL)
        port.ser.timeout = READ_BLOCK_S
        port.ser.write_timeout = self.write_timeout_s
        self._sdk, self._port = sdk, port
        self._packets = sdk.PacketHandler(2.0)
        self._sync_reads = [
            sdk.GroupSyncRead(port, self._packets, ADDR_PRESENT_POSITION, length)
            for length in READ_LENGTHS
        ]
        self._current_read = sdk.GroupSyncRead(port, self._packets, ADDR_PRESENT_CURRENT, 2)
        self._sync_write = sdk.GroupSyncWrite(port, self._packets, ADDR_GOAL_POSITION, 4)
        for dxl_id in self.ids:
            for sync_read in [*self._sync_reads, self._current_read]:
                sync_read.addParam(dxl_id)
            self._sync_write.addParam(dxl_id, [0, 0, 0, 0])
        self._last_goal = None

    def _check_device(self, k: int, dxl_id: int) -> None:
        reply = self._transaction(
            "ping", dxl_id, self._send_bare(dxl_id, "INST_PING"), 3, allow_alert=True
        )
        model = reply[0] | reply[1] << 8
        self.model_numbers[k], self.firmware_versions[k] = model, reply[2]
        expected = MODEL_NUMBERS[self.actuator.model]
        if model != expected:
            raise InputError(
                f"ids: id {dxl_id} on {self.port} has model number {model}; expected "
                f"{expected} ({self.actuator.model})"
            )
        status = self._read_value(dxl_id, ADDR_HARDWARE_ERROR, 1)
        if status:
            raise DeviceError(
                f"id {dxl_id}: Hardware Error Status 0x{status:02x} "
                f"({', '.join(hardware_error_names(status))}); reboot the actuator first"
            )
        mode = self._read_value(dxl_id, ADDR_OPERATING_MODE, 1)
        if mode != POSITION_MODE:
            raise InputError(
                f"id {dxl_id}: Operating Mode is {mode} ({OPERATING_MODES.get(mode, 'unknown')}); "
                "expected 3 (position): set it with torque off, e.g. in Dynamixel Wizard"
            )
        self.position_limits[k] = (
            self._read_value(dxl_id, ADDR_MIN_POSITION_LIMIT, 4, signed=True),
            self._read_value(dxl_id, ADDR_MAX_POSITION_LIMIT, 4, signed=True),
        )

    def _send_bare(self, dxl_id: int, instruction: str) -> Callable[[], int]:
        """A sender of the instruction the SDK names ``instruction`` (ping, reboot), with no
        parameters, to ``dxl_id``; its reply is received by :meth:`_transaction` (the SDK's
        own ``ping`` drops the firmware version and takes any reply of the right id)."""
        packet = [0] * 10
        packet[4], packet[5], packet[7] = dxl_id, 3, getattr(self._sdk, instruction)
        return lambda: self._packets.txPacket(self._port, packet)

    def _read_value(
        self, dxl_id: int, address: int, length: int, signed: bool = False, retry: bool = True
    ) -> int:
        data = self._transaction(
            f"read {ITEM_NAMES[address]} ({address})",
            dxl_id,
            lambda: self._packets.readTx(self._port, dxl_id, address, length),
            reply_length=length,
            allow_alert=address == ADDR_HARDWARE_ERROR,
            retry=retry,
        )
        return int.from_bytes(bytes(data), "little", signed=signed)

    def _transaction(
        self,
        what: str,
        dxl_id: int,
        send: Callable[[], int],
        reply_length: int,
        allow_alert: bool = False,
        retry: bool = True,
    ) -> list[int]:
        """Send one request to ``dxl_id`` (``send`` returns the SDK's result) and receive
        its status packet with ``reply_length`` bytes of parameters; returns them.

        With ``retry`` (connecting), a failed attempt is counted and retried up to
        ``retries`` times; without (inside ``read``, which counts and retries), one attempt.
        """
        for _ in range(self.retries + 1 if retry else 1):
            result = self._guarded(send)
            if result == self._sdk.COMM_SUCCESS:
                self._port.setPacketTimeout(reply_length + 11)
                data, result, error = self._receive(dxl_id, reply_length)
            if result == self._sdk.COMM_SUCCESS:
                break
            if retry:
                self.failures["connect"] += 1
        else:
            raise CommunicationError(
                f"id {dxl_id}: {what} failed on {self.port} at {self.baud} baud: "
                f"{self._packets.getTxRxResult(result)}"
            )
        if error & ~ALERT_BIT or (error & ALERT_BIT and not allow_alert):
            raise CommunicationError(
                f"id {dxl_id}: {what} refused: {self._packets.getRxPacketError(error)}"
            )
        return data

    def _receive(self, dxl_id: int, length: int) -> tuple[list[int], int, int]:
        """The status packet from ``dxl_id`` with ``length`` bytes of parameters, as
        (parameters, the SDK's result, the error byte), received within the timeout set
        for the request. Any other packet is a stale reply: counted, skipped."""
        packets, success = self._packets, self._sdk.COMM_SUCCESS
        while True:
            packet, result = self._guarded(lambda: packets.rxPacket(self._port, False))
            if result != success:
                return [], result, 0
            if (
                packet[4] == dxl_id
                and packet[7] == INST_STATUS
                and (packet[5] | packet[6] << 8) == length + 4  # + instruction, error, CRC
            ):
                return list(packet[9 : 9 + length]), result, packet[8]
            self.stale_replies += 1
            logger.debug(
                "stale reply skipped: id %d, %d bytes (waiting for id %d, %d bytes)",
                packet[4],
                (packet[5] | packet[6] << 8) - 4,
                dxl_id,
                length,
            )

    def _guarded(self, call: Callable[[], Any]) -> Any:
        """An SDK call with port errors as CommunicationError (and the port made free)."""
        try:
            return call()
        except PORT_ERRORS as exc:
            self._port.is_using = False
            raise CommunicationError(f"port: {self.port}: {exc}") from exc

    def _read_once(self) -> Measurement:
        """One sync read; a failure moves the next read on to the next of
        :data:`READ_LENGTHS` (see the module's docstring)."""
        if self._port is None:
            raise CommunicationError("read: the port is not open; call connect() first")
        try:
            return self._sync_read(self._read_turn)
        except CommunicationError:
            self._read_turn = (self._read_turn + 1) % len(READ_LENGTHS)
            raise

    def _sync_read(self, turn: int) -> Measurement:
        """The sync read of length ``READ_LENGTHS[turn]``."""
        raw, errors = self._sync_replies(
            self._sync_reads[turn], ADDR_PRESENT_POSITION, READ_LENGTHS[turn]
        )
        hardware = tuple(
            self._read_value(dxl_id, ADDR_HARDWARE_ERROR, 1, retry=False)
            if error & ALERT_BIT
            else 0
            for dxl_id, error in zip(self.ids, errors, strict=True)
        )
        position = [int.from_bytes(b[0:4], "little", signed=True) for b in raw]
        velocity = [int.from_bytes(b[4:8], "little", signed=True) for b in raw]
        current = [int.from_bytes(b[10:12], "little", signed=True) for b in raw]
        return Measurement(
            position_rad=self.actuator.angle(position),
            velocity_rad_s=self.actuator.rate(velocity),
            current_a=self.actuator.current(current),
            hardware_error=hardware,
        )

    def _sync_replies(
        self, group: Any, address: int, length: int, timeout_s: float | None = None
    ) -> tuple[list[bytes], list[int]]:
        """Send the sync read ``group`` (``length`` bytes at ``address``) and receive each
        id's reply within ``timeout_s`` (default: the backend's, else the SDK's): (its
        bytes, its error byte) per id, in the ids' order."""
        sdk, packets = self._sdk, self._packets
        result = self._guarded(group.txPacket)
        if result != sdk.COMM_SUCCESS:
            raise CommunicationError(f"sync read at {address}: {packets.getTxRxResult(result)}")
        timeout_s = self.timeout_s if timeout_s is None else timeout_s
        if timeout_s is not None:
            self._port.setPacketTimeoutMillis(timeout_s * 1000.0)
        raw, errors = [], []
        for dxl_id in self.ids:
            data, result, error = self._receive(dxl_id, length)
            if result != sdk.COMM_SUCCESS:
                raise CommunicationError(
                    f"id {dxl_id}: no valid reply to the sync read at {address}: "
                    f"{packets.getTxRxResult(result)}"
                )
            if error & ~ALERT_BIT:
                raise CommunicationError(
                    f"id {dxl_id}: sync read at {address} refused: "
                    f"{packets.getRxPacketError(error)}"
                )
            raw.append(bytes(data))
            errors.append(error)
        return raw, errors

    def _send_goals(self, goals: list[int]) -> None:
        if self._port is None:
            raise CommunicationError("write_goal: the port is not open; call connect() first")
        safe = stuffing_safe_goals(self.ids, goals, self._last_goal)
        for dxl_id, goal, sent in zip(self.ids, goals, safe, strict=True):
            if sent != goal:
                self.nudge_count += 1
                logger.debug(
                    "id %d: goal %d pulse sent as %d (SDK stuffing defect)", dxl_id, goal, sent
                )
            self._sync_write.changeParam(dxl_id, list(sent.to_bytes(4, "little", signed=True)))
        try:
            result = self._guarded(self._sync_write.txPacket)
            if result != self._sdk.COMM_SUCCESS:
                raise CommunicationError(
                    f"sync write of Goal Position: {self._packets.getTxRxResult(result)}"
                )
        except CommunicationError:
            self.failures["write"] += 1
            raise
        self._last_goal = safe
