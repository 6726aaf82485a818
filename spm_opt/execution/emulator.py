"""Two emulated Dynamixel PRO L54-50-S500-R actuators on a pseudo-terminal.

The emulator opens a pseudo-terminal, answers Protocol 2.0 on it as two actuators would
(default ids 1 and 2, joints θ1 and θ2) and drives the simulated robot
(:class:`spm_opt.execution.plant.DynamixelPlant`) in real time: before each instruction,
and whenever the line is idle, the plant is advanced to the time elapsed since serving
began (on a machine too slow for that, it drops time rather than delay replies; see
:data:`MAX_LAG_S`). A client opens ``Emulator.device`` as it would a USB-serial adapter;
the baud rate is accepted and ignored.

Instructions: ping (model 38152 and the firmware version), read, write, sync read (each
addressed actuator answers with its own status packet, in the order of the ids), sync
write (no reply) and reboot (clears the hardware error; torque off). Any other
instruction gets the instruction error (2); a packet with a bad CRC gets the CRC error (3)
if its id is one of ours; a read of addresses outside the table or a write to a read-only
or unlisted address, or to an EEPROM item (address < 562) while torque is on, gets the
access error (7); a write that covers part of an item gets the data length error (5); a
value outside its item's range (a goal position outside the position limits, a goal
velocity above the velocity limit, a goal torque above the torque limit) gets the data
range error (4); ranges the reference does not give are the item's type range, non-negative
for limits and gains. A write is applied whole or not at all. A sync write gets no reply,
so a value it carries that a write would refuse is silently dropped. While an actuator's
Hardware Error Status is non-zero, bit 7 (alert) is set in the error byte of its status
packets.

Simplifications: every instruction addressed to one id is answered whatever the Status
Return Level (891), without the Return Delay Time (9); broadcast ping is answered by
both actuators in id order, other broadcast instructions get no reply. The plant always
runs position control: Operating Mode, Homing Offset, Goal Velocity, Goal Torque and Goal
Acceleration are stored and read back but do not act. Torque Enable cannot be set while a
hardware error is pending (the write is accepted; the table keeps 0). A write of ID (7)
changes the id the actuator answers to.

The control table follows the original PRO firmware (``docs/dynamixel.md``);
Firmware Version (address 6, read-only) is added so that the table agrees with ping.

Faults (:class:`Faults`) are timed from the first goal-position write (a write or sync
write covering address 596) made while torque is on, so that a run is deterministic
relative to its own start. Their text form, ``kind:field=value,...``, is read by
:func:`parse_fault`.

A sync write gets no reply, so nothing on the bus can tell the host that one was lost:
the SDK's ``txPacket`` reports success once the port has taken the bytes. The write fault
(:class:`RefusedWrites`) therefore acts where a real failure shows: the emulator suspends
the pseudo-terminal's output (``tcflow(TCOOFF)``, as a stalled adapter or a deasserted
CTS line would), so the port takes no byte from the host and the host's writes, of goals
and of read instructions alike, time out at the port.

For tests, the emulator can record the plant's true state (:class:`StateTrace`) on the
machine's monotonic clock, which is the executor's clock too.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import select
import signal
import struct
import subprocess
import sys
import tempfile
import termios
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from spm_opt.errors import InputError
from spm_opt.execution.plant import OVERLOAD_BIT, DynamixelPlant, PlantSettings, StateTrace
from spm_opt.execution.protocol import (
    ALERT,
    BROADCAST_ID,
    MAX_ID,
    ErrorCode,
    Instruction,
    Packet,
    PacketReader,
    build_status,
    layout_consistent,
)
from spm_opt.model.params import Robot, load_robot
from spm_opt.problem import load_problem

MODEL_NUMBER = 38152
"""Model number of the L54-50-S500-R (0x9508)."""

FIRMWARE_VERSION = 0
"""Firmware version reported by ping and at address 6 unless told otherwise."""

DEFAULT_ROBOT = Path(__file__).resolve().parents[2] / "problems" / "robots" / "prototype.toml"
"""Robot file the module's entry point loads when given neither --robot nor --problem."""

INTERBYTE_TIMEOUT_S = 0.1
"""A partly received packet is dropped after this long without a byte, s."""

MAX_LAG_S = 0.01
"""Most plant time, s, made up before a reply; beyond it the plant drops time (see
:attr:`Emulator.lost_time_s`)."""

EEPROM_END = 562
"""Addresses below this are EEPROM: writable only while Torque Enable is 0."""

_INT32 = (-(2**31), 2**31 - 1)


# ----------------------------------------------------------------------- control table
@dataclass(frozen=True)
class Item:
    """One control-table item.

    Attributes
    ----------
    address, size : int
        First byte and number of bytes (little-endian; signed when ``low`` < 0).
    name : str
    writable : bool
    low, high : int
        Allowed values in table units (further narrowed for the goals, see
        :meth:`ControlTable.value_range`).
    default : int
    values : tuple of int
        If not empty, the only allowed values.
    """

    address: int
    size: int
    name: str
    writable: bool
    low: int
    high: int
    default: int = 0
    values: tuple[int, ...] = ()


MODEL_NUMBER_ITEM = Item(0, 2, "Model Number", False, 0, 65535, MODEL_NUMBER)
FIRMWARE_ITEM = Item(6, 1, "Firmware Version", False, 0, 255, FIRMWARE_VERSION)
ID_ITEM = Item(7, 1, "ID", True, 0, MAX_ID, 1)
TORQUE_LIMIT = Item(30, 2, "Torque Limit", True, 0, 32767)
VELOCITY_LIMIT = Item(32, 4, "Velocity Limit", True, 0, _INT32[1], 8000)
MAX_POSITION_LIMIT = Item(36, 4, "Max Position Limit", True, *_INT32, 180_692)
MIN_POSITION_LIMIT = Item(40, 4, "Min Position Limit", True, *_INT32, -180_692)
TORQUE_ENABLE = Item(562, 1, "Torque Enable", True, 0, 1)
VELOCITY_I_GAIN = Item(586, 2, "Velocity I Gain", True, 0, 32767, 16)
VELOCITY_P_GAIN = Item(588, 2, "Velocity P Gain", True, 0, 32767, 256)
POSITION_P_GAIN = Item(594, 2, "Position P Gain", True, 0, 32767, 32)
GOAL_POSITION = Item(596, 4, "Goal Position", True, *_INT32)
GOAL_VELOCITY = Item(600, 4, "Goal Velocity", True, *_INT32)
GOAL_TORQUE = Item(604, 2, "Goal Torque", True, -32768, 32767)
MOVING = Item(610, 1, "Moving", False, 0, 1)
PRESENT_POSITION = Item(611, 4, "Present Position", False, *_INT32)
PRESENT_VELOCITY = Item(615, 4, "Present Velocity", False, *_INT32)
PRESENT_CURRENT = Item(621, 2, "Present Current", False, -32768, 32767)
HARDWARE_ERROR_STATUS = Item(892, 1, "Hardware Error Status", False, 0, 255)

ITEMS: tuple[Item, ...] = (
    MODEL_NUMBER_ITEM,
    FIRMWARE_ITEM,
    ID_ITEM,
    Item(8, 1, "Baud Rate", True, 0, 8, 6),
    Item(9, 1, "Return Delay Time", True, 0, 254, 250),
    Item(11, 1, "Operating Mode", True, 0, 4, 3, values=(0, 1, 3, 4)),
    Item(13, 4, "Homing Offset", True, *_INT32),
    TORQUE_LIMIT,
    VELOCITY_LIMIT,
    MAX_POSITION_LIMIT,
    MIN_POSITION_LIMIT,
    Item(48, 1, "Shutdown", True, 0, 255, 58),
    TORQUE_ENABLE,
    Item(563, 1, "LED Red", True, 0, 255),
    Item(564, 1, "LED Green", True, 0, 255),
    Item(565, 1, "LED Blue", True, 0, 255),
    VELOCITY_I_GAIN,
    VELOCITY_P_GAIN,
    POSITION_P_GAIN,
    GOAL_POSITION,
    GOAL_VELOCITY,
    GOAL_TORQUE,
    Item(606, 4, "Goal Acceleration", True, 0, _INT32[1]),
    MOVING,
    PRESENT_POSITION,
    PRESENT_VELOCITY,
    PRESENT_CURRENT,
    Item(623, 2, "Present Input Voltage", False, 0, 65535, 240),
    Item(625, 1, "Present Temperature", False, 0, 255, 30),
    Item(891, 1, "Status Return Level", True, 0, 2, 2),
    HARDWARE_ERROR_STATUS,
)
"""The items of the original PRO firmware's control table (plus Firmware Version)."""

_LIVE = struct.Struct("<Biixxh")
"""Moving (610), Present Position (611), Velocity (615), two unlisted bytes, Current (621)."""

TABLE_SIZE = max(item.address + item.size for item in ITEMS)
_ITEM_AT = {item.address: item for item in ITEMS}
_OWNER: list[Item | None] = [None] * TABLE_SIZE
for _item in ITEMS:
    _OWNER[_item.address : _item.address + _item.size] = [_item] * _item.size


class ControlTable:
    """One actuator's control table: bytes, with item-level checks for writes.

    Unlisted bytes read as 0 and cannot be written.
    """

    def __init__(self) -> None:
        self.data = bytearray(TABLE_SIZE)
        for item in ITEMS:
            self.set(item, item.default)

    def get(self, item: Item) -> int:
        """An item's value (signed for signed items)."""
        raw = self.data[item.address : item.address + item.size]
        return int.from_bytes(raw, "little", signed=item.low < 0)

    def set(self, item: Item, value: int) -> None:
        """Store an item's value, without checks (values are clipped to the item's type)."""
        bits = 8 * item.size
        value = int(value) & ((1 << bits) - 1)
        self.data[item.address : item.address + item.size] = value.to_bytes(item.size, "little")

    def read(self, address: int, length: int) -> tuple[ErrorCode, bytes]:
        """Bytes ``address`` … ``address + length − 1``, or an error code and no data."""
        if length < 1:
            return ErrorCode.DATA_LENGTH, b""
        if address + length > TABLE_SIZE:
            return ErrorCode.ACCESS, b""
        return ErrorCode.NONE, bytes(self.data[address : address + length])

    def value_range(self, item: Item) -> tuple[int, int]:
        """Allowed values of an item now (goals are limited by other items)."""
        if item is GOAL_POSITION:
            return self.get(MIN_POSITION_LIMIT), self.get(MAX_POSITION_LIMIT)
        if item is GOAL_VELOCITY:
            limit = self.get(VELOCITY_LIMIT)
            return -limit, limit
        if item is GOAL_TORQUE:
            limit = self.get(TORQUE_LIMIT)
            return -limit, limit
        return item.low, item.high

    def items_covered(self, address: int, length: int) -> tuple[ErrorCode, list[Item]]:
        """The items a write of ``length`` bytes at ``address`` covers, each whole.

        Returns the data length error if it covers part of an item, the access error if
        it touches an unlisted byte or runs past the table.
        """
        end = address + length
        if length < 1:
            return ErrorCode.DATA_LENGTH, []
        if end > TABLE_SIZE:
            return ErrorCode.ACCESS, []
        items = []
        position = address
        while position < end:
            item = _ITEM_AT.get(position)
            if item is None:
                code = ErrorCode.ACCESS if _OWNER[position] is None else ErrorCode.DATA_LENGTH
                return code, []
            if position + item.size > end:
                return ErrorCode.DATA_LENGTH, []
            items.append(item)
            position += item.size
        return ErrorCode.NONE, items

    def check_write(
        self, address: int, data: bytes, torque_on: bool
    ) -> tuple[ErrorCode, list[tuple[Item, int]]]:
        """Validate a write; return its error code and, if none, the (item, value) pairs."""
        code, items = self.items_covered(address, len(data))
        if code:
            return code, []
        values = []
        for item in items:
            if not item.writable or (torque_on and item.address < EEPROM_END):
                return ErrorCode.ACCESS, []
            offset = item.address - address
            value = int.from_bytes(data[offset : offset + item.size], "little", signed=item.low < 0)
            low, high = self.value_range(item)
            if not low <= value <= high or (item.values and value not in item.values):
                return ErrorCode.DATA_RANGE, []
            values.append((item, value))
        return ErrorCode.NONE, values


# ------------------------------------------------------------------------------ faults
def _check_time(kind: str, name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0.0):
        raise InputError(f"fault {kind}: {name} must be a time >= 0 s, got {value!r}")


def _check_count(kind: str, count: int | None) -> None:
    if count is not None and (isinstance(count, bool) or not isinstance(count, int) or count < 1):
        raise InputError(f"fault {kind}: count must be an integer >= 1 (or omitted), got {count!r}")


def _check_id(kind: str, device_id: int) -> None:
    if (
        isinstance(device_id, bool)
        or not isinstance(device_id, int)
        or not 0 <= device_id <= MAX_ID
    ):
        raise InputError(f"fault {kind}: id must be an integer 0-{MAX_ID}, got {device_id!r}")


def _spec(kind: str, **values: float | int | None) -> str:
    text = ",".join(f"{k}={v!r}" for k, v in values.items() if v is not None)
    return f"{kind}:{text}"


@dataclass(frozen=True)
class DropReplies:
    """Status packets are not sent, from ``at`` s on, ``count`` of them (None: all)."""

    at: float = 0.0
    count: int | None = None

    def __post_init__(self) -> None:
        _check_time("drop", "at", self.at)
        _check_count("drop", self.count)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("drop", at=self.at, count=self.count)


@dataclass(frozen=True)
class CorruptReplies:
    """Status packets go out with a wrong CRC, from ``at`` s on, ``count`` of them."""

    at: float = 0.0
    count: int | None = None

    def __post_init__(self) -> None:
        _check_time("crc", "at", self.at)
        _check_count("crc", self.count)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("crc", at=self.at, count=self.count)


@dataclass(frozen=True)
class DelayReplies:
    """Status packets go out ``seconds`` late, from ``at`` s on, ``count`` of them."""

    seconds: float
    at: float = 0.0
    count: int | None = None

    def __post_init__(self) -> None:
        _check_time("delay", "at", self.at)
        _check_count("delay", self.count)
        if not (math.isfinite(self.seconds) and self.seconds > 0.0):
            raise InputError(f"fault delay: seconds must be > 0, got {self.seconds!r}")

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("delay", at=self.at, seconds=self.seconds, count=self.count)


@dataclass(frozen=True)
class Overload:
    """At ``at`` s the actuator ``id`` reports an overload (Hardware Error Status bit 5),
    sets the alert bit in its status packets and turns its torque off (until a reboot)."""

    id: int
    at: float = 0.0

    def __post_init__(self) -> None:
        _check_id("overload", self.id)
        _check_time("overload", "at", self.at)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("overload", id=self.id, at=self.at)


@dataclass(frozen=True)
class StuckEncoder:
    """From ``at`` s on, the actuator ``id`` reports a frozen Present Position."""

    id: int
    at: float = 0.0

    def __post_init__(self) -> None:
        _check_id("stuck", self.id)
        _check_time("stuck", "at", self.at)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("stuck", id=self.id, at=self.at)


@dataclass(frozen=True)
class RefusedWrites:
    """From ``at`` s, for ``seconds``, the line takes no byte from the host: every packet it
    sends (a sync write of goals, the instruction of a read) fails at its port.

    The pseudo-terminal's output is suspended (``tcflow(TCOOFF)``) as a stalled adapter's
    would be; a host write waits for room and fails when its write timeout expires.
    """

    seconds: float
    at: float = 0.0

    def __post_init__(self) -> None:
        _check_time("write", "at", self.at)
        if not (math.isfinite(self.seconds) and self.seconds > 0.0):
            raise InputError(f"fault write: seconds must be > 0, got {self.seconds!r}")

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("write", at=self.at, seconds=self.seconds)


Fault = DropReplies | CorruptReplies | DelayReplies | RefusedWrites | Overload | StuckEncoder

_KINDS: dict[str, type] = {
    "drop": DropReplies,
    "crc": CorruptReplies,
    "delay": DelayReplies,
    "write": RefusedWrites,
    "overload": Overload,
    "stuck": StuckEncoder,
}
_REQUIRED = {"delay": ("seconds",), "write": ("seconds",), "overload": ("id",), "stuck": ("id",)}


@dataclass(frozen=True)
class Faults:
    """Faults to inject; times in s from the first goal-position write with torque on.

    When several apply to one status packet, a drop wins over a bad CRC, which wins over
    a delay; only the fault applied uses up its count. A sync read of two ids makes two
    status packets.
    """

    drop: DropReplies | None = None
    crc: CorruptReplies | None = None
    delay: DelayReplies | None = None
    write: RefusedWrites | None = None
    overload: tuple[Overload, ...] = ()
    stuck: tuple[StuckEncoder, ...] = ()

    def specs(self) -> list[str]:
        """The faults in the text form read by :func:`parse_faults`."""
        single = [f for f in (self.drop, self.crc, self.delay, self.write) if f is not None]
        return [fault.spec() for fault in (*single, *self.overload, *self.stuck)]

    def ids(self) -> set[int]:
        """Actuator ids that the faults name."""
        return {fault.id for fault in (*self.overload, *self.stuck)}


def _number(kind: str, name: str, text: str) -> float | int:
    try:
        return int(text) if name in ("id", "count") else float(text)
    except ValueError:
        wanted = "an integer" if name in ("id", "count") else "a number of seconds"
        raise InputError(f"fault {kind}: {name} must be {wanted}, got {text!r}") from None


def parse_fault(text: str) -> Fault:
    """One fault from its text form, ``kind:field=value,...``.

    Kinds and fields (times in s from the first goal-position write with torque on;
    ``count`` omitted means every later reply):
    ``drop:at=T[,count=N]``, ``crc:at=T[,count=N]``, ``delay:at=T,seconds=S[,count=N]``,
    ``write:at=T,seconds=S``, ``overload:id=I,at=T``, ``stuck:id=I,at=T``. ``at`` defaults
    to 0.

    Raises
    ------
    InputError
        Unknown kind or field, a missing field, or a value out of range.
    """
    kind, colon, rest = text.strip().partition(":")
    kind = kind.strip().lower()
    if kind not in _KINDS:
        allowed = ", ".join(_KINDS)
        raise InputError(f"fault: unknown kind {kind!r} in {text!r} (allowed: {allowed})")
    cls = _KINDS[kind]
    allowed_fields = [f.name for f in fields(cls)]
    values: dict[str, float | int] = {}
    for part in filter(None, (p.strip() for p in rest.split(","))):
        name, equals, value = (s.strip() for s in part.partition("="))
        if name not in allowed_fields or not equals:
            raise InputError(
                f"fault {kind}: expected field=value with field one of "
                f"{', '.join(allowed_fields)}, got {part!r}"
            )
        if name in values:
            raise InputError(f"fault {kind}: field {name!r} given twice")
        values[name] = _number(kind, name, value)
    for name in _REQUIRED.get(kind, ()):
        if name not in values:
            raise InputError(f"fault {kind}: field {name!r} is required (in {text!r})")
    return cls(**values)


def parse_faults(texts: Iterable[str]) -> Faults:
    """Faults from several text forms (see :func:`parse_fault`).

    Raises
    ------
    InputError
        A text is invalid, or drop, crc, delay or write is given more than once.
    """
    single: dict[str, Fault] = {}
    overload: list[Overload] = []
    stuck: list[StuckEncoder] = []
    for text in texts:
        fault = parse_fault(text)
        if isinstance(fault, Overload):
            overload.append(fault)
        elif isinstance(fault, StuckEncoder):
            stuck.append(fault)
        else:
            kind = text.strip().partition(":")[0].strip().lower()
            if kind in single:
                raise InputError(f"fault {kind}: given more than once (allowed: once)")
            single[kind] = fault
    return Faults(
        drop=single.get("drop"),
        crc=single.get("crc"),
        delay=single.get("delay"),
        write=single.get("write"),
        overload=tuple(overload),
        stuck=tuple(stuck),
    )


class _Window:
    """A reply fault's state: active from ``at``, for ``count`` replies (None: all)."""

    def __init__(self, at: float, count: int | None) -> None:
        self.at = at
        self.remaining = count

    def take(self, t: float) -> bool:
        if t < self.at or self.remaining == 0:
            return False
        if self.remaining is not None:
            self.remaining -= 1
        return True


def _window(fault: DropReplies | CorruptReplies | DelayReplies | None) -> _Window | None:
    return None if fault is None else _Window(fault.at, fault.count)


class _Stall:
    """The write fault's state: the line's output suspended in [at, at + seconds)."""

    def __init__(self, fault: RefusedWrites, line: int) -> None:
        self.fault, self.line = fault, line
        self.suspended = False
        self.over = False

    def update(self, t: float) -> None:
        """Suspend or resume the line for the time ``t`` (s) since the fault origin."""
        if self.over or t < self.fault.at:
            return
        inside = t < self.fault.at + self.fault.seconds
        if inside != self.suspended:
            termios.tcflow(self.line, termios.TCOOFF if inside else termios.TCOON)
            self.suspended = inside
        self.over = not inside


# ---------------------------------------------------------------------------- emulator
def _valid_ids(ids: tuple[int, ...]) -> bool:
    return len(ids) == 2 and len(set(ids)) == 2 and all(0 <= int(i) <= MAX_ID for i in ids)


class _Actuator:
    def __init__(self, joint: int, device_id: int, firmware: int) -> None:
        self.joint = joint
        self.id = device_id
        self.table = ControlTable()
        self.table.set(ID_ITEM, device_id)
        self.table.set(FIRMWARE_ITEM, firmware)
        self.firmware = firmware


class Emulator:
    """Two actuators on a pseudo-terminal, driving a :class:`DynamixelPlant`.

    Parameters
    ----------
    robot : Robot
    ids : pair of int
        Ids of the actuators of θ1 and θ2 (0–252, distinct).
    start_rad : array_like, shape (2,), rad
        Joint angles at start.
    faults : Faults
    plant_settings : PlantSettings, optional
    firmware : int
        Firmware version reported by ping and at address 6.
    trace : StateTrace, optional
        Receives the plant's true state each time the plant is advanced, on the
        machine's monotonic clock (``time.monotonic``, s).

    The pseudo-terminal is opened on construction (``device`` is its path) and closed by
    :meth:`close`. As a context manager it serves in a background daemon thread;
    :meth:`serve_forever` serves in the calling thread.

    Attributes
    ----------
    device : str
        Path of the pseudo-terminal's slave side.
    plant : DynamixelPlant
    lost_time_s : float, s
        Plant time dropped because the machine could not keep up (0 on a machine that
        can): the plant then runs behind the wall clock by this much.
    """

    def __init__(
        self,
        robot: Robot,
        ids: Sequence[int] = (1, 2),
        start_rad: np.ndarray | Sequence[float] | None = None,
        faults: Faults | None = None,
        plant_settings: PlantSettings | None = None,
        firmware: int = FIRMWARE_VERSION,
        trace: StateTrace | None = None,
    ) -> None:
        ids = tuple(ids)
        if not _valid_ids(ids):
            raise InputError(f"ids: expected two distinct ids 0-{MAX_ID}, got {ids!r}")
        self.faults = faults or Faults()
        unknown = self.faults.ids() - set(ids)
        if unknown:
            raise InputError(f"fault: id {min(unknown)} is not an emulated id (allowed: {ids})")
        start = np.zeros(2) if start_rad is None else np.asarray(start_rad, dtype=float)
        self.plant = DynamixelPlant(robot, settings=plant_settings, start_rad=start)
        self._units = robot.actuator
        self._actuators = [_Actuator(j, device_id, firmware) for j, device_id in enumerate(ids)]
        self._joint_of_id = {device_id: j for j, device_id in enumerate(ids)}
        for actuator in self._actuators:
            self._load_from_plant(actuator)
        self._fault_origin: float | None = None
        self._drop = _window(self.faults.drop)
        self._crc = _window(self.faults.crc)
        self._delay = _window(self.faults.delay)
        self._events = [*self.faults.overload, *self.faults.stuck]
        self.trace = trace
        self._start: float | None = None
        self._now = 0.0
        self.lost_time_s = 0.0
        self._reader = PacketReader()
        self._outbox: deque[tuple[float, bytes]] = deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed = False
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device: str = os.ttyname(self._slave)
        self._stall = None if self.faults.write is None else _Stall(self.faults.write, self._slave)

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> Emulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Serve in a background daemon thread (no-op if it is running)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self.serve_forever, name="emulator", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the background thread (if any) and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def close(self) -> None:
        """Stop serving and close the pseudo-terminal."""
        self.stop()
        if not self._closed:
            self._closed = True
            os.close(self._master)
            os.close(self._slave)

    def serve_forever(self, stop_event: threading.Event | None = None) -> None:
        """Answer packets until ``stop_event`` (default: the one :meth:`stop` sets) is set.

        Waits on the pseudo-terminal at most until the plant's next step is due, so the
        plant keeps up with real time between packets.
        """
        stop = stop_event or self._stop
        if self._start is None:
            self._start = time.monotonic()
        master, reader, plant = self._master, self._reader, self.plant
        step = plant.settings.step_s
        last_byte = time.monotonic()
        while not stop.is_set():
            now = time.monotonic()
            timeout = self._start + plant.time_s + step - now
            if self._outbox:
                timeout = min(timeout, self._outbox[0][0] - now)
            ready, _, _ = select.select([master], [], [], min(max(timeout, 0.0), 0.05))
            if ready:
                try:
                    data = os.read(master, 65536)
                except (BlockingIOError, InterruptedError):
                    data = b""
                if data:
                    last_byte = time.monotonic()
                    for packet in reader.feed(data):
                        self._handle(packet)
            else:
                now = time.monotonic()
                self._advance(now)
                if reader.pending and now - last_byte > INTERBYTE_TIMEOUT_S:
                    reader.reset()
            if self._outbox:
                self._flush(time.monotonic())

    # ----------------------------------------------------------------- the plant
    def _load_from_plant(self, actuator: _Actuator) -> None:
        plant, units, table, j = self.plant, self._units, actuator.table, actuator.joint
        table.set(TORQUE_LIMIT, int(units.current_units(plant.current_limit_a[j])))
        table.set(VELOCITY_LIMIT, int(units.velocity_units(plant.velocity_limit_rad_s[j])))
        table.set(POSITION_P_GAIN, int(plant.position_p_gain[j]))
        table.set(VELOCITY_P_GAIN, int(plant.velocity_p_gain[j]))
        table.set(VELOCITY_I_GAIN, int(plant.velocity_i_gain[j]))
        table.set(GOAL_POSITION, int(units.pulses(plant.goal_position_rad[j])))
        table.set(TORQUE_ENABLE, int(plant.torque_enabled[j]))

    def _refresh(self) -> None:
        """Copy the plant's measured state into both tables (before a read)."""
        plant = self.plant
        position = plant.present_position_pulses().tolist()
        velocity = plant.present_velocity_units().tolist()
        current = plant.present_current_units().tolist()
        moving = plant.moving().tolist()
        error = plant.hardware_error.tolist()
        torque = plant.torque_enabled.tolist()
        for actuator in self._actuators:
            data, j = actuator.table.data, actuator.joint
            _LIVE.pack_into(data, MOVING.address, moving[j], position[j], velocity[j], current[j])
            data[HARDWARE_ERROR_STATUS.address] = error[j]
            data[TORQUE_ENABLE.address] = torque[j]

    def _advance(self, now: float) -> None:
        """Bring the plant to ``now`` and fire the faults that are due.

        A plant more than :data:`MAX_LAG_S` behind (the machine could not keep up) drops
        the excess instead of catching up, so that replies stay prompt.
        """
        self._now = now
        lag = now - self._start - self.plant.time_s
        if lag > MAX_LAG_S:
            self._start += lag - MAX_LAG_S
            self.lost_time_s += lag - MAX_LAG_S
        self.plant.advance_to(now - self._start)
        if self.trace is not None:
            self.trace.record(now, self.plant)
        if self._stall is not None and self._fault_origin is not None:
            self._stall.update(now - self._fault_origin)
        if self._events and self._fault_origin is not None:
            t = now - self._fault_origin
            for event in [e for e in self._events if t >= e.at]:
                j = self._joint_of_id[event.id]
                if isinstance(event, Overload):
                    self.plant.trigger_hardware_error(j, OVERLOAD_BIT)
                else:
                    self.plant.encoder_stuck[j] = True
                self._events.remove(event)

    def _apply(self, actuator: _Actuator, item: Item, value: int) -> None:
        """Store a checked value and pass it on to the plant."""
        plant, units, j = self.plant, self._units, actuator.joint
        table = actuator.table
        table.set(item, value)
        if item is GOAL_POSITION:
            plant.goal_position_rad[j] = float(units.angle(value))
            if self._fault_origin is None and plant.torque_enabled.any():
                self._fault_origin = self._now
        elif item is TORQUE_ENABLE:
            plant.enable_torque(j, bool(value))
            table.set(TORQUE_ENABLE, int(plant.torque_enabled[j]))
            table.set(GOAL_POSITION, int(units.pulses(plant.goal_position_rad[j])))
        elif item is VELOCITY_LIMIT:
            plant.velocity_limit_rad_s[j] = float(units.rate(value))
        elif item is TORQUE_LIMIT:
            plant.current_limit_a[j] = float(units.current(value))
        elif item is POSITION_P_GAIN:
            plant.position_p_gain[j] = value
        elif item is VELOCITY_P_GAIN:
            plant.velocity_p_gain[j] = value
        elif item is VELOCITY_I_GAIN:
            plant.velocity_i_gain[j] = value
        elif item is ID_ITEM:
            actuator.id = value

    def _write(self, actuator: _Actuator, address: int, data: bytes) -> ErrorCode:
        torque_on = bool(self.plant.torque_enabled[actuator.joint])
        code, values = actuator.table.check_write(address, data, torque_on)
        for item, value in values:
            self._apply(actuator, item, value)
        return code

    # ------------------------------------------------------------------- packets
    def _by_id(self, device_id: int) -> _Actuator | None:
        return next((a for a in self._actuators if a.id == device_id), None)

    def _addressed(self, device_id: int) -> list[_Actuator]:
        if device_id == BROADCAST_ID:
            return self._actuators
        actuator = self._by_id(device_id)
        return [] if actuator is None else [actuator]

    def _handle(self, packet: Packet) -> None:
        self._advance(time.monotonic())
        broadcast = packet.id == BROADCAST_ID
        targets = self._addressed(packet.id)
        if not targets:
            return
        if not packet.crc_ok:
            if not broadcast:
                self._reply(targets[0], ErrorCode.CRC)
            return
        handler = self._HANDLERS.get(packet.instruction)
        if handler is None:
            if not broadcast:
                self._reply(targets[0], ErrorCode.INSTRUCTION)
            return
        if not layout_consistent(packet.instruction, packet.params):
            if not broadcast:
                self._reply(targets[0], ErrorCode.DATA_LENGTH)
            return
        handler(self, packet, targets, broadcast)

    def _ping(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        for actuator in targets:
            data = MODEL_NUMBER.to_bytes(2, "little") + bytes((actuator.firmware,))
            self._reply(actuator, ErrorCode.NONE, data)

    def _read(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        if broadcast:
            return
        params = packet.params
        self._refresh()
        code, data = targets[0].table.read(params[0] | params[1] << 8, params[2] | params[3] << 8)
        self._reply(targets[0], code, data)

    def _write_instruction(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        table = targets[0].table
        # the reading that covers whole items: an unstuffed sender's data may hold FF FF FD FD
        params = next(
            (
                p
                for p in packet.readings
                if len(p) >= 3 and not table.items_covered(p[0] | p[1] << 8, len(p) - 2)[0]
            ),
            packet.params,
        )
        address = params[0] | params[1] << 8
        codes = [self._write(actuator, address, params[2:]) for actuator in targets]
        if not broadcast:
            self._reply(targets[0], codes[0])

    def _sync_read(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        params = packet.params
        address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
        self._refresh()
        for actuator in filter(None, map(self._by_id, params[4:])):
            code, data = actuator.table.read(address, length)
            self._reply(actuator, code, data)

    def _sync_write(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        params = packet.params
        address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
        for offset in range(4, len(params), length + 1):
            actuator = self._by_id(params[offset])
            if actuator is not None:
                self._write(actuator, address, params[offset + 1 : offset + 1 + length])

    def _reboot(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        for actuator in targets:
            self.plant.reboot(actuator.joint)
            actuator.table.set(TORQUE_ENABLE, 0)
            actuator.table.set(HARDWARE_ERROR_STATUS, 0)
        if not broadcast:
            self._reply(targets[0], ErrorCode.NONE)

    _HANDLERS: dict[int, Callable[[Emulator, Packet, list[_Actuator], bool], None]] = {
        Instruction.PING: _ping,
        Instruction.READ: _read,
        Instruction.WRITE: _write_instruction,
        Instruction.SYNC_READ: _sync_read,
        Instruction.SYNC_WRITE: _sync_write,
        Instruction.REBOOT: _reboot,
    }

    # -------------------------------------------------------------------- replies
    def _reply(self, actuator: _Actuator, code: ErrorCode, data: bytes = b"") -> None:
        error = int(code) | (ALERT if self.plant.hardware_error[actuator.joint] else 0)
        packet = build_status(actuator.id, error, data)
        send_at = self._now
        if self._fault_origin is not None:
            t = self._now - self._fault_origin
            if self._drop is not None and self._drop.take(t):
                return
            if self._crc is not None and self._crc.take(t):
                packet = packet[:-2] + bytes((packet[-2] ^ 0xFF, packet[-1] ^ 0xFF))
            elif self._delay is not None and self._delay.take(t):
                send_at += self.faults.delay.seconds
        if self._outbox or send_at > self._now:
            self._outbox.append(
                (max(send_at, self._outbox[-1][0] if self._outbox else 0.0), packet)
            )
        else:
            self._send(packet)

    def _flush(self, now: float) -> None:
        while self._outbox and self._outbox[0][0] <= now:
            self._send(self._outbox.popleft()[1])

    def _send(self, packet: bytes) -> None:
        """Write to the line; what the client does not take in time is lost."""
        with contextlib.suppress(BlockingIOError):
            os.write(self._master, packet)


# ------------------------------------------------------------------------ entry points
def serve(
    robot: Robot,
    ids: Sequence[int],
    start_rad: np.ndarray | Sequence[float],
    faults: Faults,
    seed: int,
    announce: Callable[[str], None],
    trace_path: str | Path | None = None,
) -> None:
    """Serve in the calling (main) thread until SIGINT or SIGTERM.

    Parameters
    ----------
    robot, ids, start_rad, faults
        As for :class:`Emulator`; ``start_rad`` in rad.
    seed : int
        Seed of the plant's sensor noise.
    announce : callable
        Called once with the device path, before serving.
    trace_path : path, optional
        Where to save the plant's true state (:class:`StateTrace`, ``.npz``) when serving
        ends.
    """
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        trace = None if trace_path is None else StateTrace()
        emulator = Emulator(robot, ids, start_rad, faults, PlantSettings(seed=seed), trace=trace)
        try:
            announce(emulator.device)
            emulator.serve_forever(stop)
        finally:
            emulator.close()
            if trace is not None:
                trace.save(trace_path)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def parse_ids(text: str) -> tuple[int, int]:
    """Two actuator ids from ``"1,2"``; raises InputError naming ``--ids``."""
    try:
        ids = tuple(int(part) for part in text.split(","))
    except ValueError:
        ids = ()
    if not _valid_ids(ids):
        raise InputError(f"--ids: expected two distinct ids 0-{MAX_ID} as 'a,b', got {text!r}")
    return ids[0], ids[1]


def parse_angles_deg(text: str) -> np.ndarray:
    """Two joint angles in degrees from ``"a,b"``, returned in rad; raises InputError."""
    try:
        angles = np.array([float(part) for part in text.split(",")])
    except ValueError:
        angles = np.array([])
    if angles.shape != (2,) or not np.all(np.isfinite(angles)):
        raise InputError(f"--start-deg: expected two angles in degrees as 'a,b', got {text!r}")
    return np.deg2rad(angles)


def _load_robot(robot_file: str | None, problem_file: str | None) -> Robot:
    if problem_file is not None:
        return load_problem(problem_file).robot
    return load_robot(robot_file or DEFAULT_ROBOT)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m spm_opt.execution.emulator``.

    Prints the device path as the first line of stdout, then serves until SIGINT or
    SIGTERM. Returns the exit status (2 for bad input).
    """
    parser = argparse.ArgumentParser(
        prog="python -m spm_opt.execution.emulator",
        description="Emulate two Dynamixel L54-50-S500-R actuators on a pseudo-terminal.",
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--robot", help=f"robot TOML file (default {DEFAULT_ROBOT})")
    source.add_argument("--problem", help="problem TOML file; its robot is used")
    parser.add_argument("--ids", default="1,2", help="ids of the θ1 and θ2 actuators")
    parser.add_argument("--start-deg", default="0,0", help="joint angles at start, deg")
    parser.add_argument("--fault", action="append", default=[], help="fault to inject (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    parser.add_argument("--trace", help="save the plant's true state here (.npz) at exit")
    args = parser.parse_args(argv)
    try:
        faults = parse_faults(args.fault)
        ids = parse_ids(args.ids)
        start = parse_angles_deg(args.start_deg)
        robot = _load_robot(args.robot, args.problem)
        serve(
            robot,
            ids,
            start,
            faults,
            args.seed,
            lambda device: print(device, flush=True),
            trace_path=args.trace,
        )
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


@dataclass(frozen=True)
class SpawnedEmulator:
    """An emulator running in a child process: its device path and the process."""

    device: str
    process: subprocess.Popen


@contextlib.contextmanager
def spawn_emulator(
    robot_file: str | Path | None = None,
    *,
    problem_file: str | Path | None = None,
    ids: Sequence[int] = (1, 2),
    start_deg: Sequence[float] = (0.0, 0.0),
    faults: Faults | None = None,
    seed: int = 0,
    trace_path: str | Path | None = None,
    startup_timeout_s: float = 30.0,
) -> Iterator[SpawnedEmulator]:
    """Run the emulator in a child process (out of this process's GIL) while in the block.

    Parameters
    ----------
    robot_file, problem_file : path, optional
        Robot TOML, or a problem TOML whose robot is used (default: the prototype).
    ids, start_deg, faults, seed
        As for :class:`Emulator`; ``start_deg`` in degrees.
    trace_path : path, optional
        Where the child saves the plant's true state when it ends (read it after the
        block with :meth:`StateTrace.load`).
    startup_timeout_s : float, s
        How long to wait for the child to announce its device.

    Yields
    ------
    SpawnedEmulator
        ``device`` to open, ``process`` to inspect; the child is terminated on exit.

    Raises
    ------
    RuntimeError
        The child did not announce a device in time (its stderr is in the message).
    """
    command = [sys.executable, "-m", "spm_opt.execution.emulator"]
    if problem_file is not None:
        command += ["--problem", str(problem_file)]
    elif robot_file is not None:
        command += ["--robot", str(robot_file)]
    command += ["--ids", ",".join(str(i) for i in ids)]
    command += ["--start-deg", ",".join(repr(float(a)) for a in start_deg), "--seed", str(seed)]
    for spec in (faults or Faults()).specs():
        command += ["--fault", spec]
    if trace_path is not None:
        command += ["--trace", str(trace_path)]
    with tempfile.TemporaryFile() as errors:
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=errors)
        try:
            ready, _, _ = select.select([process.stdout], [], [], startup_timeout_s)
            line = process.stdout.readline().decode().strip() if ready else ""
            if not line:
                process.kill()
                process.wait()
                errors.seek(0)
                message = errors.read().decode(errors="replace").strip().splitlines()
                raise RuntimeError(
                    "emulator child did not announce its device"
                    + (f": {message[-1]}" if message else "")
                )
            yield SpawnedEmulator(line, process)
        finally:
            if process.poll() is None:
                process.terminate()
                try:
                    process.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            process.stdout.close()


if __name__ == "__main__":
    sys.exit(main())
