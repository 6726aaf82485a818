"""The OpenIGTLink message codec (header versions 1 and 2): bytes in, bytes out, no sockets
and no threads.

A message is a 58-byte header and a body. The header, big-endian like every number of the
protocol: the header version (uint16), TYPE (char[12]) and DEVICE_NAME (char[20]), both
ASCII padded with NULs, a timestamp (uint64: seconds since 1970 in the high 32 bits, the
fraction of a second times 2³² in the low 32), BODY_SIZE (uint64, bytes) and the CRC-64 of
the body (ECMA-182's polynomial, not reflected, no initial value, no final xor: the
reference library's ``crc64`` of ``igtl_util.c``). A version 2 body holds an extended
header, the content and metadata (:func:`content` returns the content); a version 1 body is
the content. The layouts of the contents are those of the protocol's documents (TRANSFORM,
STATUS, STRING, POINT, POLYDATA in ``Documents/Protocol`` of OpenIGTLink).

What arrives from the network is never trusted: every fault of a received message raises
:class:`MalformedMessage` (one line naming the field and its value), to be logged and the
message dropped; :class:`StreamReader` frames a TCP stream with bounded memory. Wrong
arguments to the packing functions are the program's mistakes: they raise ``ValueError``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

HEADER_BYTES = 58
"""Size of a message's header, bytes."""
MAX_BODY_BYTES = 96 << 10
"""The largest body the server reads, bytes (96 KiB). The messages it takes are small: a
TRANSFORM holds 48 bytes, a flap of 12 points 1,632, a STRING at most 65,539; a POINT list
of this size holds 722 points. A larger bound only lets a client keep the server's thread,
and the interpreter lock the control loop shares with it, busy for longer."""
KINDS_RECEIVED = ("TRANSFORM", "POINT", "STRING", "STATUS")
"""The message types whose contents the server decodes (the others are dropped)."""
STATUS_CODES = {
    0: "invalid packet",
    1: "OK",
    2: "unknown error",
    3: "panic mode",
    4: "not found",
    5: "access denied",
    6: "busy",
    7: "time out",
    8: "overflow",
    9: "checksum error",
    10: "configuration error",
    11: "not enough resource",
    12: "unknown instruction",
    13: "not ready",
    14: "manual mode",
    15: "disabled",
    16: "not present",
    17: "unknown version",
    18: "hardware failure",
    19: "shut down",
}
"""The status codes of a STATUS message (the protocol's ``status.md``, ``igtl_status.h``)."""

_HEADER = struct.Struct(">H12s20sQQQ")
# a version 2 body's first 12 bytes: EXT_HEADER_SIZE, METADATA_HEADER_SIZE, METADATA_SIZE, MSG_ID
_EXTENDED_HEADER = struct.Struct(">HHII")
_STATUS = struct.Struct(">Hq20s")
_STRING = struct.Struct(">HH")
_POLYDATA = struct.Struct(">10I")
_TRANSFORM_BYTES = 48
_POINT = np.dtype(
    [
        ("name", "S64"),
        ("group", "S32"),
        ("rgba", "u1", (4,)),
        ("xyz", ">f4", (3,)),
        ("diameter", ">f4"),
        ("owner", "S20"),
    ]
)  # 136 bytes, packed
_ASCII, _UTF8 = 3, 106  # MIBenums of US-ASCII (a STRING's default) and UTF-8
_ENCODINGS = {_ASCII: "ascii", _UTF8: "utf-8"}
_CRC_POLYNOMIAL = 0x42F0E1EBA9EA3693
_CRC_MASK = (1 << 64) - 1


class MalformedMessage(ValueError):
    """A received message that is not sound; the text is one line naming the field and its
    value. Network input, logged and dropped: not a user's
    :class:`~spm_opt.base.errors.InputError`."""


class StreamBroken(MalformedMessage):
    """A header that is not sound: the stream can no longer be framed, and its connection is
    to be closed.

    Attributes
    ----------
    messages : tuple
        What the stream gave before the broken header, in order (messages and
        :class:`MalformedMessage`), as :meth:`StreamReader.feed` would have returned them.
    """

    def __init__(self, reason: str, messages: Sequence[Message | MalformedMessage] = ()) -> None:
        super().__init__(reason)
        self.messages = tuple(messages)


@dataclass(frozen=True)
class Header:
    """A message's header.

    Attributes
    ----------
    version : int
        Header version, 1 or 2.
    kind : str
        TYPE, e.g. ``"TRANSFORM"``.
    device : str
        DEVICE_NAME (may be empty).
    timestamp_s : float
        Seconds since 1970 (0 when unused).
    body_bytes : int
        BODY_SIZE, bytes.
    crc : int
        The CRC-64 the sender computed of the body.
    """

    version: int
    kind: str
    device: str
    timestamp_s: float
    body_bytes: int
    crc: int


@dataclass(frozen=True)
class Message:
    """A header and its body (for version 2, extended header, content and metadata)."""

    header: Header
    body: bytes


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 56
        for _ in range(8):
            crc = ((crc << 1) ^ _CRC_POLYNOMIAL if crc >> 63 else crc << 1) & _CRC_MASK
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc64(data: bytes) -> int:
    """The CRC-64 of ``data`` that OpenIGTLink's header carries (ECMA-182's polynomial
    0x42F0E1EBA9EA3693, not reflected, initial value 0, no final xor): a byte at a time from
    a table."""
    crc = 0
    table = _CRC_TABLE
    for byte in data:
        crc = table[(crc >> 56) ^ byte] ^ ((crc << 8) & _CRC_MASK)
    return crc


def _header_field(text: str, size: int, field: str) -> bytes:
    """``text`` as a header's char[size]: printable ASCII, NUL-padded."""
    if len(text) > size or not (text.isascii() and text.isprintable()):
        raise ValueError(f"{field} {text!r} is not at most {size} printable ASCII characters")
    return text.encode("ascii").ljust(size, b"\0")


def pack(kind: str, device: str, body: bytes, timestamp_s: float, version: int = 1) -> bytes:
    """A whole message: header and body.

    Parameters
    ----------
    kind : str
        TYPE: 1 to 12 printable ASCII characters.
    device : str
        DEVICE_NAME: at most 20 printable ASCII characters.
    body : bytes
        The content (from :func:`transform_body`, :func:`string_body`, ...). Version 2 puts
        it after an extended header of 12 bytes (no metadata, message ID 0).
    timestamp_s : float
        Seconds since 1970, 0 <= t < 2³² (0 for unused).
    version : int
        Header version, 1 or 2.
    """
    if version not in (1, 2):
        raise ValueError(f"header version {version}; only 1 and 2 are written")
    if not kind:
        raise ValueError("TYPE is empty")
    if not 0.0 <= timestamp_s < 2.0**32:
        raise ValueError(f"timestamp {timestamp_s!r} s is not in [0, 2**32) s")
    timestamp = round(timestamp_s * 2.0**32)  # exact: a float scaled by a power of 2
    if version == 2:
        body = _EXTENDED_HEADER.pack(_EXTENDED_HEADER.size, 0, 0, 0) + body
    header = _HEADER.pack(
        version,
        _header_field(kind, 12, "TYPE"),
        _header_field(device, 20, "DEVICE_NAME"),
        timestamp,
        len(body),
        crc64(body),
    )
    return header + body


def _read_header_field(raw: bytes, field: str) -> str:
    """A header's char[n]: printable ASCII then NULs only."""
    text, _, padding = raw.partition(b"\0")
    if padding.strip(b"\0") or any(not 0x20 <= byte <= 0x7E for byte in text):
        raise MalformedMessage(f"{field} {raw!r} is not printable ASCII padded with NULs")
    return text.decode("ascii")


def read_header(data: bytes) -> Header:
    """The header in ``data`` (exactly :data:`HEADER_BYTES` bytes); :class:`MalformedMessage`
    for a wrong length, a version other than 1 or 2, a TYPE or DEVICE_NAME that is not
    printable ASCII padded with NULs, an empty TYPE, or a body above :data:`MAX_BODY_BYTES`."""
    if len(data) != HEADER_BYTES:
        raise MalformedMessage(f"header of {len(data)} bytes; a header is {HEADER_BYTES}")
    version, raw_kind, raw_device, timestamp, body_bytes, crc = _HEADER.unpack(data)
    if version not in (1, 2):
        raise MalformedMessage(f"header version {version}; only 1 and 2 are read")
    kind = _read_header_field(raw_kind, "TYPE")
    if not kind:
        raise MalformedMessage("TYPE is empty")
    device = _read_header_field(raw_device, "DEVICE_NAME")
    if body_bytes > MAX_BODY_BYTES:
        raise MalformedMessage(f"body of {body_bytes} bytes; at most {MAX_BODY_BYTES} read")
    timestamp_s = (timestamp >> 32) + (timestamp & 0xFFFFFFFF) / 2.0**32
    return Header(version, kind, device, timestamp_s, body_bytes, crc)


def content(message: Message) -> bytes:
    """The content of ``message``, bytes: the whole body for version 1; for version 2 the
    body less its extended header (first) and its metadata (last). :class:`MalformedMessage`
    when the extended header's sizes do not fit the body."""
    body = message.body
    if message.header.version == 1:
        return body
    if len(body) < _EXTENDED_HEADER.size:
        raise MalformedMessage(
            f"version 2 body of {len(body)} bytes; its extended header takes "
            f"{_EXTENDED_HEADER.size}"
        )
    extended, metadata_header, metadata, _ = _EXTENDED_HEADER.unpack_from(body)
    end = len(body) - metadata_header - metadata
    if extended < _EXTENDED_HEADER.size or end < extended:
        raise MalformedMessage(
            f"extended header of {extended} bytes and metadata of {metadata_header}+{metadata}"
            f" bytes do not fit a body of {len(body)} bytes"
        )
    return body[extended:end]


def _check_length(kind: str, data: bytes, expected: int) -> None:
    if len(data) != expected:
        raise MalformedMessage(f"{kind} content of {len(data)} bytes; it takes {expected}")


def transform_body(matrix_mm: np.ndarray) -> bytes:
    """A TRANSFORM's content (48 bytes) from a (4, 4) homogeneous matrix, translation in mm:
    12 float32, the rotation's columns then the translation (R11 R21 R31 R12 ... TX TY TZ).
    The bottom row, not sent, must be (0, 0, 0, 1)."""
    matrix = np.asarray(matrix_mm, dtype=np.float64)
    if matrix.shape != (4, 4):
        raise ValueError(f"transform of shape {matrix.shape}; it takes (4, 4)")
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-9):
        raise ValueError(f"transform's bottom row {matrix[3].tolist()} is not (0, 0, 0, 1)")
    values = np.concatenate([matrix[:3, :3].T.ravel(), matrix[:3, 3]]).astype(">f4")
    if not np.all(np.isfinite(values)):
        raise ValueError("transform is not finite in float32")
    return values.tobytes()


def read_transform(body: bytes) -> np.ndarray:
    """The (4, 4) homogeneous matrix (float64, translation in mm) of a TRANSFORM's content;
    :class:`MalformedMessage` unless it is 48 bytes of finite float32."""
    _check_length("TRANSFORM", body, _TRANSFORM_BYTES)
    values = np.frombuffer(body, dtype=">f4").astype(np.float64)
    if not np.all(np.isfinite(values)):
        raise MalformedMessage(f"TRANSFORM values {values.tolist()} are not all finite")
    matrix = np.eye(4)
    matrix[:3, :3] = values[:9].reshape(3, 3).T
    matrix[:3, 3] = values[9:]
    return matrix


def _text_field(text: str, size: int, field: str) -> bytes:
    """``text`` as a content's char[size]: UTF-8, NUL-padded (no NUL when it fills it)."""
    raw = text.encode("utf-8")
    if len(raw) > size or b"\0" in raw:
        raise ValueError(f"{field} {text!r} is not at most {size} bytes of UTF-8 without NUL")
    return raw.ljust(size, b"\0")


def _read_text(raw: bytes, field: str) -> str:
    """A content's char field: the UTF-8 text before its first NUL."""
    try:
        return raw.partition(b"\0")[0].decode("utf-8")
    except UnicodeDecodeError:
        raise MalformedMessage(f"{field} {raw!r} is not UTF-8") from None


def status_body(code: int, subcode: int, error_name: str, message: str) -> bytes:
    """A STATUS's content: code (uint16, one of :data:`STATUS_CODES`), subcode (int64,
    device-specific), error name (char[20]) and the status message, NUL-terminated."""
    if code not in STATUS_CODES:
        raise ValueError(f"status code {code} is not one of 0 to {max(STATUS_CODES)}")
    if not -(2**63) <= subcode < 2**63:
        raise ValueError(f"status subcode {subcode} is not an int64")
    name = _text_field(error_name, 20, "status error name")
    text = message.encode("utf-8")
    if b"\0" in text:
        raise ValueError(f"status message {message!r} holds a NUL")
    return _STATUS.pack(code, subcode, name) + text + b"\0"


def read_status(body: bytes) -> tuple[int, int, str, str]:
    """Code, subcode, error name and status message of a STATUS's content (at least 30
    bytes; a message after them ends with a NUL)."""
    if len(body) < _STATUS.size:
        raise MalformedMessage(f"STATUS content of {len(body)} bytes; it takes at least 30")
    code, subcode, raw_name = _STATUS.unpack_from(body)
    text = body[_STATUS.size :]
    if text and not text.endswith(b"\0"):
        raise MalformedMessage(f"STATUS message {text[-40:]!r} does not end with a NUL")
    return (
        code,
        subcode,
        _read_text(raw_name, "STATUS error name"),
        _read_text(text, "STATUS message"),
    )


def string_body(text: str) -> bytes:
    """A STRING's content: encoding (uint16, US-ASCII (3) when ``text`` is ASCII, else UTF-8
    (106)), length (uint16, bytes, at most 65,535) and the bytes."""
    encoding = _ASCII if text.isascii() else _UTF8
    raw = text.encode(_ENCODINGS[encoding])
    if len(raw) > 0xFFFF:
        raise ValueError(f"string of {len(raw)} bytes; a STRING holds at most 65535")
    return _STRING.pack(encoding, len(raw)) + raw


def read_string(body: bytes) -> str:
    """The text of a STRING's content; :class:`MalformedMessage` for a length that is not
    the content's, an encoding other than US-ASCII (3) and UTF-8 (106), or bytes that are
    not in it."""
    if len(body) < _STRING.size:
        raise MalformedMessage(f"STRING content of {len(body)} bytes; it takes at least 4")
    encoding, length = _STRING.unpack_from(body)
    _check_length("STRING", body, _STRING.size + length)
    if encoding not in _ENCODINGS:
        raise MalformedMessage(f"STRING encoding {encoding} is not US-ASCII (3) or UTF-8 (106)")
    raw = body[_STRING.size :]
    try:
        return raw.decode(_ENCODINGS[encoding])
    except UnicodeDecodeError:
        raise MalformedMessage(f"STRING {raw[:40]!r} is not {_ENCODINGS[encoding]}") from None


def point_body(
    names: Sequence[str],
    points_mm: np.ndarray,
    group: str = "",
    rgba: tuple[int, int, int, int] = (255, 0, 0, 255),
    diameter_mm: float = 1.0,
    owner: str = "",
) -> bytes:
    """A POINT's content, 136 bytes a point: name (char[64]), group (char[32]), RGBA
    (4 uint8), x y z (float32, mm), diameter (float32, mm), owner (char[20]); the strings
    UTF-8 and NUL-padded, the group, colour, diameter and owner the same for every point."""
    points = np.asarray(points_mm, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] != len(names):
        raise ValueError(f"points of shape {points.shape} for {len(names)} names; it takes (n, 3)")
    if not np.all(np.isfinite(points.astype(np.float32))):
        raise ValueError("points are not finite in float32")
    if len(rgba) != 4 or any(not 0 <= value <= 255 for value in rgba):
        raise ValueError(f"RGBA {tuple(rgba)} is not 4 integers in [0, 255]")
    if not math.isfinite(diameter_mm) or diameter_mm < 0.0:
        raise ValueError(f"point diameter {diameter_mm!r} mm is not finite and >= 0")
    records = np.zeros(len(names), dtype=_POINT)
    records["name"] = [_text_field(name, 64, "point name") for name in names]
    records["group"] = _text_field(group, 32, "point group")
    records["rgba"] = rgba
    records["xyz"] = points
    records["diameter"] = diameter_mm
    records["owner"] = _text_field(owner, 20, "point owner")
    return records.tobytes()


def read_points(body: bytes) -> tuple[list[str], np.ndarray]:
    """Names and positions ((n, 3) float64, mm) of a POINT's content; :class:`MalformedMessage`
    for a length that is not a multiple of 136, a name that is not UTF-8, or a coordinate that
    is not finite."""
    if len(body) % _POINT.itemsize:
        raise MalformedMessage(
            f"POINT content of {len(body)} bytes; it takes a multiple of {_POINT.itemsize}"
        )
    records = np.frombuffer(body, dtype=_POINT)
    points = records["xyz"].astype(np.float64)
    if not np.all(np.isfinite(points)):
        index = int(np.flatnonzero(~np.all(np.isfinite(points), axis=1))[0])
        raise MalformedMessage(f"POINT {index} at {points[index].tolist()} mm is not finite")
    names = [
        _read_text(bytes(raw), f"POINT {index} name") for index, raw in enumerate(records["name"])
    ]
    return names, points


def _cells(cells: Sequence[Sequence[int]], points: int, field: str) -> tuple[int, bytes]:
    """A POLYDATA cell array: per cell its count then its point indices, uint32."""
    flat: list[int] = []
    for cell in cells:
        if len(cell) == 0 or any(not 0 <= index < points for index in cell):
            raise ValueError(f"{field} cell {list(cell)} is not point indices in [0, {points})")
        flat += [len(cell), *cell]
    return len(cells), np.asarray(flat, dtype=">u4").tobytes()


def polydata_body(
    points_mm: np.ndarray,
    lines: Sequence[Sequence[int]] = (),
    vertices: Sequence[Sequence[int]] = (),
) -> bytes:
    """A POLYDATA's content (``polydata.md``): the counts NPOINTS, NVERTICES, SIZE_VERTICES,
    NLINES, SIZE_LINES, NPOLYGONS, SIZE_POLYGONS, NTRIANGLE_STRIPS, SIZE_TRIANGLE_STRIPS and
    NATTRIBUTES (uint32, sizes in bytes), the points (float32 x y z, mm), then the vertices
    and the lines, each cell its count and its point indices (uint32); no polygons, triangle
    strips or attributes."""
    points = np.asarray(points_mm, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points of shape {points.shape}; it takes (n, 3)")
    coordinates = points.astype(">f4")
    if not np.all(np.isfinite(coordinates)):
        raise ValueError("points are not finite in float32")
    vertex_count, vertex_bytes = _cells(vertices, len(points), "vertex")
    line_count, line_bytes = _cells(lines, len(points), "line")
    counts = _POLYDATA.pack(
        len(points), vertex_count, len(vertex_bytes), line_count, len(line_bytes), 0, 0, 0, 0, 0
    )
    return counts + coordinates.tobytes() + vertex_bytes + line_bytes


_READERS: dict[str, Callable[[bytes], object]] = {
    "TRANSFORM": read_transform,
    "POINT": read_points,
    "STRING": read_string,
    "STATUS": read_status,
}


def check_body(header: Header, body: bytes) -> None:
    """:class:`MalformedMessage` (naming the message's TYPE and DEVICE_NAME) unless ``body``
    has the header's size and, for a kind of :data:`KINDS_RECEIVED`, its CRC, a version 2
    body's sizes fit and its content reads (its length for its kind, its encoding, finite
    values). Other kinds pass unread, their CRC unchecked."""
    try:
        if len(body) != header.body_bytes:
            raise MalformedMessage(
                f"body of {len(body)} bytes; the header claims {header.body_bytes}"
            )
        if header.kind not in _READERS:
            return  # dropped unread: not worth its CRC's time on the server's thread
        crc = crc64(body)
        if crc != header.crc:
            raise MalformedMessage(f"body's CRC {crc:#018x} is not the header's {header.crc:#018x}")
        _READERS[header.kind](content(Message(header, body)))
    except MalformedMessage as error:
        raise MalformedMessage(f"{header.kind} from {header.device!r}: {error}") from None


class StreamReader:
    """Splits a TCP byte stream into messages: :meth:`feed` takes what arrived and returns
    the messages it completed.

    A message whose header is sound but whose body is not (its CRC, its length for its
    kind, its content: see :func:`check_body`) comes out as a :class:`MalformedMessage`, and
    the stream goes on at the next header; a message of a kind not in
    :data:`KINDS_RECEIVED` comes out as it is (the caller drops it). A header that is not
    sound (see :func:`read_header`: names not ASCII, a bad version, a body above
    :data:`MAX_BODY_BYTES`) means the stream can no longer be framed: :meth:`feed` raises
    :class:`StreamBroken`, and raises it again if fed more, and the caller closes the
    connection.

    Memory is bounded: it holds at most :data:`HEADER_BYTES` + :data:`MAX_BODY_BYTES` of the
    stream (a partial header, or one body, allocated at its header's size), whatever the
    chunks fed.
    """

    def __init__(self) -> None:
        self._head = bytearray()  # the partial header, < HEADER_BYTES
        self._header: Header | None = None  # the header of the body being read
        self._body = bytearray()  # that body, its header's size
        self._filled = 0  # bytes of it received
        self._broken: str | None = None

    def feed(self, data: bytes) -> list[Message | MalformedMessage]:
        """The messages (and malformed ones) that ``data``, the next bytes of the stream,
        completes, in order. :class:`StreamBroken` for a header that is not sound, holding
        the messages before it."""
        if self._broken is not None:
            raise StreamBroken(self._broken)
        items: list[Message | MalformedMessage] = []
        view = memoryview(data).cast("B")
        while True:
            if self._header is None:
                taken = HEADER_BYTES - len(self._head)
                self._head += view[:taken]
                view = view[taken:]
                if len(self._head) < HEADER_BYTES:
                    return items
                try:
                    self._header = read_header(bytes(self._head))
                except MalformedMessage as error:
                    self._broken = f"stream broken: {error}"
                    raise StreamBroken(self._broken, items) from None
                self._head.clear()
                self._body = bytearray(self._header.body_bytes)
                self._filled = 0
            taken = min(len(view), self._header.body_bytes - self._filled)
            self._body[self._filled : self._filled + taken] = view[:taken]
            self._filled += taken
            view = view[taken:]
            if self._filled < self._header.body_bytes:
                return items
            items.append(self._complete())

    def _complete(self) -> Message | MalformedMessage:
        """The message whose body has all come; the reader then waits for a header."""
        assert self._header is not None
        message = Message(self._header, bytes(self._body))
        self._header, self._body = None, bytearray()
        try:
            check_body(message.header, message.body)
        except MalformedMessage as error:
            return error
        return message
