"""Dynamixel Protocol 2.0 packets: CRC, byte stuffing, building and parsing. No I/O.

A packet is ``FF FF FD 00 | ID | LEN_L LEN_H | INST | params | CRC_L CRC_H``; LEN counts
the instruction, the (stuffed) parameters and the CRC. A status packet is the same with
INST = 0x55 and the error byte as its first parameter. Inside INST + params every
``FF FF FD`` is followed by an extra ``FD`` (byte stuffing), and LEN and the CRC cover the
stuffed bytes.

The parser tolerates the defect of ``dynamixel-sdk`` 4.1.0, which never stuffs: a packet
whose data contains ``FF FF FD`` arrives unstuffed, with the unstuffed length. Because the
parser frames packets by LEN, such a packet is still found; its parameters are then read
both ways, stripping the ``FD`` after each ``FF FF FD FD`` (the standard reading) or
taking them as they came (the SDK's reading), and :attr:`Packet.readings` lists the
readings that differ, the one consistent with the instruction's parameter layout first.
An ``FF FF FD`` followed by anything but ``FD`` can only be the unstuffed form, so it is
kept as it is.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum

HEADER = b"\xff\xff\xfd\x00"
"""The four bytes that open every packet."""

BROADCAST_ID = 0xFE
MAX_ID = 0xFC
"""Largest device id (0–252 are devices, 0xFE is broadcast)."""

MAX_LENGTH = 1024
"""Largest LEN the parser accepts (as the SDK); a larger one is taken for noise."""

_STUFF_PATTERN = b"\xff\xff\xfd"
_STUFFED_PATTERN = b"\xff\xff\xfd\xfd"


class Instruction(IntEnum):
    """Instruction codes of Protocol 2.0."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    BULK_READ = 0x92
    BULK_WRITE = 0x93


class ErrorCode(IntEnum):
    """Error numbers in bits 0–6 of a status packet's error byte."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


ALERT = 0x80
"""Bit 7 of the error byte: the device has a hardware error (read address 892)."""


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 of Protocol 2.0 (poly 0x8005, init 0, no reflection, no final XOR).

    Parameters
    ----------
    data : bytes-like
        Every byte from the first header byte to the last parameter.
    crc : int
        A running CRC to continue from (0 to start).

    Returns
    -------
    int
        The CRC, 0–0xFFFF; it is sent low byte first.
    """
    table = _CRC_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
    return crc


def stuff(data: bytes) -> bytes:
    """Byte stuffing: an ``FD`` after every ``FF FF FD`` of ``data`` (INST + params)."""
    if _STUFF_PATTERN not in data:
        return bytes(data)
    return bytes(data).replace(_STUFF_PATTERN, _STUFFED_PATTERN)


def unstuff(data: bytes) -> bytes:
    """Undo :func:`stuff`: drop the ``FD`` after every ``FF FF FD FD``.

    An ``FF FF FD`` that is not followed by ``FD`` (only an unstuffed sender makes one) is
    kept as it is.
    """
    if _STUFFED_PATTERN not in data:
        return bytes(data)
    return bytes(data).replace(_STUFFED_PATTERN, _STUFF_PATTERN)


def _frame(device_id: int, body: bytes) -> bytes:
    stuffed = stuff(body)
    length = len(stuffed) + 2
    packet = HEADER + bytes((device_id, length & 0xFF, length >> 8)) + stuffed
    crc = crc16(packet)
    return packet + bytes((crc & 0xFF, crc >> 8))


def build_instruction(device_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet, stuffed, with LEN and CRC.

    Parameters
    ----------
    device_id : int
        0–252, or :data:`BROADCAST_ID`.
    instruction : int
        An :class:`Instruction` code.
    params : bytes
        The parameters, unstuffed (little-endian values).
    """
    return _frame(device_id, bytes((instruction,)) + bytes(params))


def build_status(device_id: int, error: int, data: bytes = b"") -> bytes:
    """A status packet (instruction 0x55), stuffed, with LEN and CRC.

    Parameters
    ----------
    device_id : int
    error : int
        The error byte: an :class:`ErrorCode` in bits 0–6, :data:`ALERT` in bit 7.
    data : bytes
        The returned data, unstuffed.
    """
    return _frame(device_id, bytes((Instruction.STATUS, error)) + bytes(data))


def _word(data: bytes, offset: int) -> int:
    return data[offset] | data[offset + 1] << 8


def layout_consistent(instruction: int, params: bytes) -> bool:
    """Whether ``params`` has the parameter layout ``instruction`` requires.

    Checks lengths only (e.g. a read has exactly 4 parameter bytes, a sync write a whole
    number of ``[id, data…]`` blocks). Unknown instructions are taken as consistent.
    """
    n = len(params)
    if instruction in (Instruction.PING, Instruction.ACTION, Instruction.REBOOT):
        return n == 0
    if instruction == Instruction.READ:
        return n == 4
    if instruction in (Instruction.WRITE, Instruction.REG_WRITE):
        return n >= 3
    if instruction == Instruction.FACTORY_RESET:
        return n == 1
    if instruction == Instruction.CLEAR:
        return n == 5
    if instruction == Instruction.STATUS:
        return n >= 1
    if instruction == Instruction.SYNC_READ:
        return n >= 5
    if instruction == Instruction.SYNC_WRITE:
        if n < 4:
            return False
        block = _word(params, 2) + 1
        return block > 1 and n > 4 and (n - 4) % block == 0
    if instruction == Instruction.BULK_READ:
        return n > 0 and n % 5 == 0
    if instruction == Instruction.BULK_WRITE:
        offset = 0
        while offset + 5 <= n:
            offset += 5 + _word(params, offset + 3)
        return n > 0 and offset == n
    return True


@dataclass(frozen=True)
class Packet:
    """One packet found by :class:`PacketReader`.

    Attributes
    ----------
    id : int
    instruction : int
        :class:`Instruction` code (0x55 for a status packet).
    readings : tuple of bytes
        The parameters, unstuffed: one reading, or two when the packet holds an
        ``FF FF FD FD`` that may be stuffing or an unstuffed sender's data; the reading
        consistent with the instruction's layout comes first.
    crc_ok : bool
        False when the CRC did not match (the readings are then as received).
    """

    id: int
    instruction: int
    readings: tuple[bytes, ...]
    crc_ok: bool = True

    @property
    def params(self) -> bytes:
        """The most likely reading of the parameters."""
        return self.readings[0]

    @property
    def error(self) -> int:
        """A status packet's error byte."""
        return self.params[0]

    @property
    def data(self) -> bytes:
        """A status packet's data (the parameters after the error byte)."""
        return self.params[1:]


def _readings(instruction: int, raw: bytes) -> tuple[bytes, ...]:
    standard = unstuff(raw)
    if standard == raw:
        return (raw,)
    if layout_consistent(instruction, standard) or not layout_consistent(instruction, raw):
        return (standard, raw)
    return (raw, standard)


class PacketReader:
    """Incremental parser: feed it bytes as they arrive, get whole packets out.

    It finds the header ``FF FF FD 00``, reads LEN, waits for LEN more bytes, checks the
    CRC and unstuffs the parameters. Bytes before a header are skipped; a header with an
    impossible LEN (below 3 or above :data:`MAX_LENGTH`) is taken for noise and the search
    resumes one byte later. A packet with a bad CRC is returned with ``crc_ok=False`` and
    its LEN bytes are consumed.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()

    @property
    def pending(self) -> int:
        """Number of bytes held, waiting for the rest of a packet."""
        return len(self._buffer)

    def reset(self) -> None:
        """Drop a partly received packet (e.g. after a pause on the line)."""
        self._buffer.clear()

    def feed(self, data: bytes | Iterable[int]) -> list[Packet]:
        """Add received bytes; return the packets they complete, in order."""
        buffer = self._buffer
        buffer.extend(data)
        packets = []
        while buffer:
            start = buffer.find(HEADER)
            if start < 0:
                # keep what may be the start of a header
                keep = next((k for k in (3, 2, 1) if buffer.endswith(HEADER[:k])), 0)
                del buffer[: len(buffer) - keep]
                return packets
            if start:
                del buffer[:start]
            if len(buffer) < 7:
                return packets
            length = buffer[5] | buffer[6] << 8
            if length < 3 or length > MAX_LENGTH:
                del buffer[:1]
                continue
            end = 7 + length
            if len(buffer) < end:
                return packets
            crc_ok = crc16(buffer[: end - 2]) == (buffer[end - 2] | buffer[end - 1] << 8)
            instruction = buffer[7]
            raw = bytes(buffer[8 : end - 2])
            readings = _readings(instruction, raw) if crc_ok else (raw,)
            packets.append(Packet(buffer[4], instruction, readings, crc_ok))
            del buffer[:end]
        return packets
