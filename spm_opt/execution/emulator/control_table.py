"""The control table of an emulated L54-50-S500-R: its items, their ranges and the bytes.

The items follow the original PRO firmware (``docs/dynamixel.md``); Firmware Version
(address 6, read-only) is added so that the table agrees with ping.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from spm_opt.execution.protocol import (
    MAX_ID,
    ErrorCode,
)
from spm_opt.model.actuator import VELOCITY_LIMIT_UNITS

MODEL_NUMBER = 38152
"""Model number of the L54-50-S500-R (0x9508)."""

FIRMWARE_VERSION = 0
"""Firmware version reported by ping and at address 6 unless told otherwise."""

EEPROM_END = 562
"""Addresses below this are EEPROM: writable only while Torque Enable is 0."""

_INT32 = (-(2**31), 2**31 - 1)


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
VELOCITY_LIMIT = Item(32, 4, "Velocity Limit", True, 0, _INT32[1], VELOCITY_LIMIT_UNITS)
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

LIVE_LAYOUT = struct.Struct("<Biixxh")
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
