"""The OpenIGTLink codec (spm_opt.navigation.igtl) against code nobody here wrote.

The references: a bit-by-bit CRC-64 written here and crcmod's (the one pyigtl puts in its
headers), with the check value of the CRC-64 used by the reference library (ECMA-182's
polynomial, not reflected: 0x6C40DF5F0B497347 for b"123456789"); pyigtl's packing and
unpacking of TRANSFORM, STRING and POINT and its header parser, both ways; pyigtl's
POLYDATA packing (its unpacking is broken, and it packs vertices in the machine's byte
order, so vertices are read here with struct); STATUS bytes laid out here with struct after
the protocol's status.md and igtl_status.h (pyigtl has no STATUS). Messages fed to the
stream reader are framed here with struct and crcmod, not with the code under test.
"""

import math
import re
import struct
import tracemalloc

import numpy as np
import pyigtl
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyigtl.messages import CRC64 as PYIGTL_CRC64

from spm_opt.navigation import igtl

FAST = settings(max_examples=60, deadline=None)
CHECK_VALUE = 0x6C40DF5F0B497347  # CRC-64/ECMA-182 (not reflected, init 0, no xor) of "123456789"
MASK = (1 << 64) - 1
HEADER = struct.Struct(">H12s20sQQQ")
NAME_CHARACTERS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-"


def crc64_bitwise(data: bytes) -> int:
    """ECMA-182's CRC-64 a bit at a time: polynomial 0x42F0E1EBA9EA3693, MSB first."""
    crc = 0
    for byte in data:
        crc ^= byte << 56
        for _ in range(8):
            crc = ((crc << 1) ^ 0x42F0E1EBA9EA3693) & MASK if crc & (1 << 63) else (crc << 1) & MASK
    return crc


def frame(
    kind: bytes,
    device: bytes,
    body: bytes,
    *,
    version: int = 1,
    crc: int | None = None,
    body_size: int | None = None,
) -> bytes:
    """A message framed with struct and crcmod, the CRC and the BODY_SIZE overridable."""
    size = len(body) if body_size is None else body_size
    checksum = PYIGTL_CRC64(body) if crc is None else crc
    return HEADER.pack(version, kind, device, 0, size, checksum) + body


def pyigtl_read(data: bytes) -> tuple[dict, pyigtl.MessageBase]:
    """pyigtl's header fields and message of the bytes of one message."""
    fields = pyigtl.MessageBase.parse_header(data[: igtl.HEADER_BYTES])
    message = pyigtl.MessageBase.create_message(fields["message_type"])
    message.unpack(fields, data[igtl.HEADER_BYTES : igtl.HEADER_BYTES + fields["body_size"]])
    return fields, message


def read_one(data: bytes) -> igtl.Message:
    """The one message in ``data``, through the stream reader (so checked)."""
    (item,) = igtl.StreamReader().feed(data)
    assert isinstance(item, igtl.Message), item
    return item


def float32(values: np.ndarray) -> np.ndarray:
    return np.asarray(values, dtype=np.float32).astype(np.float64)


@st.composite
def poses(draw: st.DrawFn) -> np.ndarray:
    """A (4, 4) pose: the rotation of a random quaternion, a translation within ±500 mm."""
    q = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)))
    norm = np.linalg.norm(q)
    if norm < 0.1:
        q, norm = np.array([1.0, 0.0, 0.0, 0.0]), 1.0
    w, x, y, z = q / norm
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = draw(st.lists(st.floats(-500.0, 500.0), min_size=3, max_size=3))
    return pose


names = st.text(alphabet=NAME_CHARACTERS, min_size=1, max_size=64)
coordinate = st.floats(-500.0, 500.0, allow_nan=False)


@st.composite
def point_lists(draw: st.DrawFn) -> tuple[list[str], np.ndarray]:
    count = draw(st.integers(1, 12))
    labels = draw(st.lists(names, min_size=count, max_size=count))
    points = draw(
        st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=count, max_size=count)
    )
    return labels, np.array(points, dtype=np.float64)


# --- the CRC ------------------------------------------------------------------------------


def test_crc64_has_the_check_value_of_ecma_182():
    assert igtl.crc64(b"123456789") == CHECK_VALUE
    assert crc64_bitwise(b"123456789") == CHECK_VALUE
    assert PYIGTL_CRC64(b"123456789") == CHECK_VALUE
    assert igtl.crc64(b"") == 0


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=600))
def test_crc64_is_the_bitwise_crc_and_crcmods(data):
    assert igtl.crc64(data) == crc64_bitwise(data) == PYIGTL_CRC64(data)


def test_the_crc_pyigtl_writes_in_its_header_is_ours():
    data = pyigtl.StringMessage("G28 home", device_name="CMD_1").pack()
    header = igtl.read_header(data[:58])
    assert header.crc == igtl.crc64(data[58:]) != 0
    assert struct.unpack(">Q", data[50:58])[0] == header.crc


# --- the header ---------------------------------------------------------------------------


def test_pack_writes_the_header_of_the_protocol():
    data = igtl.pack("STRING", "RunInfo", igtl.string_body("ok"), 1_700_000_000.25)
    version, kind, device, timestamp, size, crc = HEADER.unpack(data[:58])
    assert (version, kind, device) == (1, b"STRING" + 6 * b"\0", b"RunInfo" + 13 * b"\0")
    assert (timestamp >> 32, timestamp & 0xFFFFFFFF) == (1_700_000_000, 1 << 30)
    assert size == len(data) - 58 == 6 and crc == PYIGTL_CRC64(data[58:])


@FAST
@given(st.floats(0.0, 4.0e9), st.text(alphabet=NAME_CHARACTERS, max_size=20))
def test_pyigtl_reads_our_header_and_we_read_its(timestamp_s, device):
    ours = igtl.pack("TRANSFORM", device, igtl.transform_body(np.eye(4)), timestamp_s)
    fields = pyigtl.MessageBase.parse_header(ours[:58])
    assert fields["message_type"] == "TRANSFORM" and fields["device_name"] == device
    assert fields["header_version"] == 1 and fields["body_size"] == 48
    assert fields["timestamp"] == pytest.approx(timestamp_s, abs=1e-6)
    theirs = pyigtl.TransformMessage(np.eye(4), timestamp=timestamp_s, device_name=device).pack()
    header = igtl.read_header(theirs[:58])
    assert (header.version, header.kind, header.device, header.body_bytes) == (
        1,
        "TRANSFORM",
        device,
        48,
    )
    assert header.timestamp_s == pytest.approx(timestamp_s, abs=1e-6)


@pytest.mark.parametrize(
    ("header", "says"),
    [
        (HEADER.pack(1, b"STRING", b"Tool", 0, 4, 0)[:57], "header of 57 bytes"),
        (HEADER.pack(7, b"STRING", b"Tool", 0, 4, 0), "header version 7"),
        (HEADER.pack(0, b"STRING", b"Tool", 0, 4, 0), "header version 0"),
        (HEADER.pack(1, b"", b"Tool", 0, 4, 0), "TYPE is empty"),
        (HEADER.pack(1, b"STR\x01NG", b"Tool", 0, 4, 0), "TYPE b'STR\\x01NG"),
        (HEADER.pack(1, b"STRING", "Outil é".encode(), 0, 4, 0), "DEVICE_NAME b'Outil \\xc3"),
        (HEADER.pack(1, b"STRING", b"Tool\0junk", 0, 4, 0), "DEVICE_NAME b'Tool\\x00junk"),
        (HEADER.pack(1, b"IMAGE", b"Tool", 0, 2**63, 0), "body of 9223372036854775808 bytes"),
        (HEADER.pack(1, b"IMAGE", b"", 0, (96 << 10) + 1, 0), "body of 98305 bytes"),
    ],
)
def test_a_header_that_is_not_sound_says_which_field_and_value(header, says):
    with pytest.raises(igtl.MalformedMessage) as error:
        igtl.read_header(header)
    assert says in str(error.value) and "\n" not in str(error.value)


def test_a_body_size_is_read_up_to_the_bound_and_named_above_it():
    header = igtl.read_header(HEADER.pack(2, b"IMAGE", b"", 0, igtl.MAX_BODY_BYTES, 0))
    assert (header.version, header.device, header.body_bytes) == (2, "", 96 << 10)
    with pytest.raises(
        igtl.MalformedMessage, match=r"^body of 9223372036854775808 bytes; at most 98304 read$"
    ):
        igtl.read_header(HEADER.pack(1, b"IMAGE", b"", 0, 2**63, 0))


@pytest.mark.parametrize(
    ("kind", "device", "timestamp_s", "version"),
    [
        ("", "Tool", 0.0, 1),
        ("TRANSFORMATION", "Tool", 0.0, 1),
        ("TRANSFORM", "Outil é", 0.0, 1),
        ("TRANSFORM", "x" * 21, 0.0, 1),
        ("TRANSFORM", "Tool", -1.0, 1),
        ("TRANSFORM", "Tool", math.nan, 1),
        ("TRANSFORM", "Tool", 2.0**32, 1),
        ("TRANSFORM", "Tool", 0.0, 3),
    ],
)
def test_pack_refuses_what_the_header_cannot_hold(kind, device, timestamp_s, version):
    with pytest.raises(ValueError):
        igtl.pack(kind, device, igtl.transform_body(np.eye(4)), timestamp_s, version)


# --- TRANSFORM ----------------------------------------------------------------------------


@FAST
@given(poses())
def test_a_transform_we_pack_is_pyigtls_matrix(pose):
    data = igtl.pack("TRANSFORM", "ToolToRAS", igtl.transform_body(pose), 12.5)
    fields, message = pyigtl_read(data)
    assert fields["device_name"] == "ToolToRAS"
    np.testing.assert_array_equal(message.matrix, float32(pose))


@FAST
@given(poses())
def test_a_transform_pyigtl_packs_is_our_matrix(pose):
    data = pyigtl.TransformMessage(pose, timestamp=3.0, device_name="Registration").pack()
    message = read_one(data)
    assert (message.header.kind, message.header.device) == ("TRANSFORM", "Registration")
    matrix = igtl.read_transform(igtl.content(message))
    assert matrix.dtype == np.float64
    np.testing.assert_array_equal(matrix, float32(pose))


def test_a_transform_is_laid_out_by_columns_then_translation():
    pose = np.array([[1, 2, 3, 10], [4, 5, 6, 20], [7, 8, 9, 30], [0, 0, 0, 1]], dtype=float)
    values = struct.unpack(">12f", igtl.transform_body(pose))
    assert values == (1, 4, 7, 2, 5, 8, 3, 6, 9, 10, 20, 30)


def test_a_transform_that_cannot_be_sent_or_read_is_refused():
    with pytest.raises(ValueError):
        igtl.transform_body(np.eye(3))
    skewed = np.eye(4)
    skewed[3, 0] = 0.5
    with pytest.raises(ValueError):
        igtl.transform_body(skewed)
    with pytest.raises(igtl.MalformedMessage, match="44 bytes"):
        igtl.read_transform(bytes(44))
    with pytest.raises(igtl.MalformedMessage, match="not all finite"):
        igtl.read_transform(struct.pack(">12f", *([math.inf] + [0.0] * 11)))


# --- STRING -------------------------------------------------------------------------------


@FAST
@given(st.text(alphabet=st.characters(min_codepoint=0, max_codepoint=127), max_size=300))
def test_an_ascii_string_goes_both_ways_with_pyigtl(text):
    body = igtl.string_body(text)
    assert struct.unpack(">HH", body[:4]) == (3, len(text))
    _, message = pyigtl_read(igtl.pack("STRING", "RunInfo", body, 0.0))
    assert message.string == text
    theirs = pyigtl.StringMessage(text, device_name="CMD_7").pack()
    assert igtl.read_string(igtl.content(read_one(theirs))) == text


@FAST
@given(st.text(min_size=1, max_size=200).filter(lambda text: not text.isascii()))
def test_a_string_that_is_not_ascii_goes_as_utf8(text):
    body = igtl.string_body(text)
    assert struct.unpack(">HH", body[:4]) == (106, len(text.encode()))
    _, message = pyigtl_read(igtl.pack("STRING", "RunInfo", body, 0.0))
    assert message.string == text
    assert igtl.read_string(body) == text


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (struct.pack(">HH", 3, 10) + b"abc", "STRING content of 7 bytes; it takes 14"),
        (struct.pack(">HH", 3, 1) + b"abc", "STRING content of 7 bytes; it takes 5"),
        (b"\0\x03", "STRING content of 2 bytes"),
        (struct.pack(">HH", 4, 3) + b"abc", "STRING encoding 4"),
        (struct.pack(">HH", 3, 2) + "é".encode(), "is not ascii"),
        (struct.pack(">HH", 106, 2) + b"\xff\xfe", "is not utf-8"),
    ],
)
def test_a_string_that_is_not_sound_is_malformed(body, says):
    with pytest.raises(igtl.MalformedMessage, match=re.escape(says)):
        igtl.read_string(body)


def test_a_string_too_long_for_its_length_field_is_refused():
    assert len(igtl.string_body("x" * 65535)) == 65539
    with pytest.raises(ValueError):
        igtl.string_body("x" * 65536)


# --- POINT --------------------------------------------------------------------------------


@FAST
@given(point_lists())
def test_points_we_pack_are_pyigtls(point_list):
    labels, points = point_list
    body = igtl.point_body(labels, points, "Flap", (0, 128, 255, 200), 2.5, "CT")
    assert len(body) == 136 * len(labels)
    _, message = pyigtl_read(igtl.pack("POINT", "Flap", body, 0.0))
    assert message.names == labels
    np.testing.assert_array_equal(np.array(message.positions), float32(points))
    assert message.groups == ["Flap"] * len(labels) and message.owners == ["CT"] * len(labels)
    assert message.rgba_colors == [(0, 128, 255, 200)] * len(labels)
    assert message.diameters == [2.5] * len(labels)


@FAST
@given(point_lists())
def test_points_pyigtl_packs_are_ours(point_list):
    labels, points = point_list
    data = pyigtl.PointMessage(positions=points, names=labels, device_name="Flap").pack()
    read_labels, read_points = igtl.read_points(igtl.content(read_one(data)))
    assert read_labels == labels
    assert read_points.dtype == np.float64 and read_points.shape == (len(labels), 3)
    np.testing.assert_array_equal(read_points, float32(points))


def test_points_named_in_utf8_and_filling_their_field_come_back():
    labels = ["é" * 32, "x" * 64, "Entry"]
    points = np.arange(9.0).reshape(3, 3)
    assert igtl.read_points(igtl.point_body(labels, points))[0] == labels
    with pytest.raises(ValueError):
        igtl.point_body(["x" * 65], points[:1])


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (bytes(135), "POINT content of 135 bytes; it takes a multiple of 136"),
        (igtl.point_body(["a", "b"], np.zeros((2, 3)))[:200], "200 bytes"),
    ],
)
def test_points_of_a_wrong_length_are_malformed(body, says):
    with pytest.raises(igtl.MalformedMessage, match=re.escape(says)):
        igtl.read_points(body)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_point_that_is_not_finite_is_malformed(value):
    data = pyigtl.PointMessage(positions=[[0, 0, 0], [1, value, 2]], names=["a", "b"]).pack()
    with pytest.raises(igtl.MalformedMessage, match="POINT 1 at"):
        igtl.read_points(data[58:])


# --- STATUS -------------------------------------------------------------------------------


def test_the_status_codes_are_the_protocols():
    assert sorted(igtl.STATUS_CODES) == list(range(20))
    assert (igtl.STATUS_CODES[1], igtl.STATUS_CODES[13], igtl.STATUS_CODES[19]) == (
        "OK",
        "not ready",
        "shut down",
    )


def test_a_status_is_laid_out_as_status_md_says():
    body = igtl.status_body(13, -2, "NOT_READY", "homing the joints")
    assert body == struct.pack(">Hq20s", 13, -2, b"NOT_READY") + b"homing the joints\0"
    assert igtl.read_status(body) == (13, -2, "NOT_READY", "homing the joints")


@pytest.mark.parametrize(
    ("body", "read"),
    [
        (struct.pack(">Hq20s", 1, 0, b"OK"), (1, 0, "OK", "")),
        (struct.pack(">Hq20s", 1, 0, b"OK") + b"\0", (1, 0, "OK", "")),
        (struct.pack(">Hq20s", 7, 2**62, b"T" * 20) + b"lost\0", (7, 2**62, "T" * 20, "lost")),
    ],
)
def test_statuses_laid_out_here_are_read(body, read):
    assert igtl.read_status(body) == read


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (bytes(29), "STATUS content of 29 bytes"),
        (struct.pack(">Hq20s", 1, 0, b"OK") + b"no end", "does not end with a NUL"),
        (struct.pack(">Hq20s", 1, 0, b"\xff") + b"\0", "error name b'\\xff"),
    ],
)
def test_a_status_that_is_not_sound_is_malformed(body, says):
    with pytest.raises(igtl.MalformedMessage, match=re.escape(says)):
        igtl.read_status(body)


def test_a_status_that_cannot_be_sent_is_refused():
    for code, name, message in [(20, "X", ""), (1, "x" * 21, ""), (1, "OK", "a\0b")]:
        with pytest.raises(ValueError):
            igtl.status_body(code, 0, name, message)


# --- POLYDATA -----------------------------------------------------------------------------


def read_polydata(body: bytes) -> tuple[np.ndarray, list[list[int]], list[list[int]]]:
    """Points, vertices and lines of a POLYDATA body laid out as polydata.md says."""
    counts = struct.unpack_from(">10I", body)
    assert counts[5:] == (0, 0, 0, 0, 0)  # no polygons, strips or attributes
    offset = 40
    points = np.array(struct.unpack_from(f">{3 * counts[0]}f", body, offset)).reshape(-1, 3)
    offset += 12 * counts[0]
    arrays = []
    for cells, size in (counts[1:3], counts[3:5]):
        flat = list(struct.unpack_from(f">{size // 4}I", body, offset))
        offset += size
        cell_list = []
        while flat:
            count, flat = flat[0], flat[1:]
            cell_list.append(flat[:count])
            flat = flat[count:]
        assert len(cell_list) == cells
        arrays.append(cell_list)
    assert offset == len(body)
    return points, arrays[0], arrays[1]


def test_polydata_lines_are_packed_as_pyigtl_packs_them():
    points = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 5.5]])
    lines = [[0, 1, 2, 3, 0], [1, 3]]
    flat = [5, 0, 1, 2, 3, 0, 2, 1, 3]
    theirs = pyigtl.PolyDataMessage(points=points, lines=flat, device_name="Plan").pack()
    ours = igtl.pack("POLYDATA", "Plan", igtl.polydata_body(points, lines), 0.0)
    assert ours[58:] == theirs[58:]
    assert igtl.read_header(ours[:58]).crc == igtl.read_header(theirs[:58]).crc


@FAST
@given(
    st.integers(1, 30).flatmap(
        lambda n: st.tuples(
            st.lists(st.tuples(coordinate, coordinate, coordinate), min_size=n, max_size=n),
            st.lists(st.lists(st.integers(0, n - 1), min_size=1, max_size=6), max_size=4),
            st.lists(st.lists(st.integers(0, n - 1), min_size=1, max_size=3), max_size=4),
        )
    )
)
def test_polydata_is_laid_out_as_polydata_md_says(drawn):
    points, lines, vertices = drawn
    read, read_vertices, read_lines = read_polydata(igtl.polydata_body(points, lines, vertices))
    np.testing.assert_array_equal(read, float32(points))
    assert (read_vertices, read_lines) == (vertices, lines)


def test_polydata_refuses_cells_of_no_point_or_points_it_lacks():
    points = np.zeros((3, 3))
    for lines in ([[0, 3]], [[]], [[-1, 0]]):
        with pytest.raises(ValueError):
            igtl.polydata_body(points, lines)


# --- version 2: extended header and metadata ----------------------------------------------


@FAST
@given(poses())
def test_a_version_2_message_of_pyigtl_with_metadata_is_read(pose):
    message = pyigtl.TransformMessage(pose, device_name="Registration")
    message.header_version = 2
    message.message_id = 41
    message.metadata = {"Status": "OK", "Patient": "Doe"}  # pyigtl packs only ASCII values
    received = read_one(message.pack())
    assert received.header.version == 2
    assert len(received.body) > 12 + 48
    np.testing.assert_array_equal(igtl.read_transform(igtl.content(received)), float32(pose))


def test_a_version_2_message_we_pack_is_read_by_pyigtl():
    pose = np.eye(4)
    pose[:3, 3] = [1.0, -2.0, 3.5]
    data = igtl.pack("TRANSFORM", "ToolToRAS", igtl.transform_body(pose), 5.0, version=2)
    fields, message = pyigtl_read(data)
    assert fields["header_version"] == 2 and fields["body_size"] == 12 + 48
    assert message.metadata == {} and message.message_id == 0
    np.testing.assert_array_equal(message.matrix, pose)
    assert igtl.read_transform(igtl.content(read_one(data)))[2, 3] == 3.5


@pytest.mark.parametrize(
    "extended",
    [
        struct.pack(">HHII", 12, 0, 100, 0),  # metadata larger than the body
        struct.pack(">HHII", 8, 0, 0, 0),  # an extended header shorter than its own fields
        struct.pack(">HHII", 200, 0, 0, 0),  # longer than the body
        struct.pack(">HHII", 12, 40, 20, 0),  # metadata overlapping the extended header
    ],
)
def test_a_version_2_body_whose_sizes_do_not_fit_is_malformed(extended):
    body = extended + bytes(48)
    message = igtl.Message(igtl.read_header(frame(b"TRANSFORM", b"T", body, version=2)[:58]), body)
    with pytest.raises(igtl.MalformedMessage, match="do not fit"):
        igtl.content(message)
    (item,) = igtl.StreamReader().feed(frame(b"TRANSFORM", b"T", body, version=2))
    assert isinstance(item, igtl.MalformedMessage) and "do not fit" in str(item)
    with pytest.raises(igtl.MalformedMessage, match="extended header takes 12"):
        igtl.content(igtl.Message(message.header, body[:10]))


# --- the stream reader --------------------------------------------------------------------


def good_messages() -> list[bytes]:
    """Messages of each kind received, from pyigtl and framed here, and one of a kind the
    server does not decode."""
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 3.0]
    return [
        pyigtl.TransformMessage(pose, timestamp=1.25, device_name="Registration").pack(),
        pyigtl.StringMessage("START", device_name="CMD_1").pack(),
        pyigtl.PointMessage(positions=[[1, 2, 3], [4, 5, 6]], names=["a", "b"]).pack(),
        frame(b"STATUS", b"Slicer", struct.pack(">Hq20s", 1, 0, b"OK") + b"fine\0"),
        frame(b"IMAGE", b"CT", bytes(range(7))),
        frame(b"GET_STATUS", b"", b""),
    ]


MALFORMED = {
    "bad CRC": frame(b"TRANSFORM", b"Tool", bytes(48), crc=PYIGTL_CRC64(bytes(48)) ^ 1),
    "TRANSFORM of 44 bytes": frame(b"TRANSFORM", b"Tool", bytes(44)),
    "STRING claiming more": frame(b"STRING", b"CMD_2", struct.pack(">HH", 3, 10) + b"abc"),
    "unknown encoding": frame(b"STRING", b"CMD_3", struct.pack(">HH", 4, 3) + b"abc"),
    "POINT not finite": pyigtl.PointMessage(positions=[[0, math.nan, 0]], names=["a"]).pack(),
    "STATUS without NUL": frame(b"STATUS", b"S", struct.pack(">Hq20s", 1, 0, b"OK") + b"x"),
}
SAYS = {
    "bad CRC": "TRANSFORM from 'Tool': body's CRC",
    "TRANSFORM of 44 bytes": "TRANSFORM from 'Tool': TRANSFORM content of 44 bytes; it takes 48",
    "STRING claiming more": "STRING from 'CMD_2': STRING content of 7 bytes; it takes 14",
    "unknown encoding": "STRING from 'CMD_3': STRING encoding 4",
    "POINT not finite": "POINT from '': POINT 0 at [0.0, nan, 0.0] mm is not finite",
    "STATUS without NUL": "STATUS from 'S': STATUS message b'x' does not end with a NUL",
}
BROKEN = {
    "non-ASCII device name": frame(b"STRING", "Outil é".encode(), igtl.string_body("x")),
    "version 7": frame(b"STRING", b"CMD", igtl.string_body("x"), version=7),
    "body of 2**63 bytes": frame(b"STRING", b"CMD", b"", body_size=2**63),
    "empty TYPE": frame(b"", b"CMD", igtl.string_body("x")),
}


def outcome(items: list) -> list:
    """Messages as they are, malformed ones as their type and text (comparable)."""
    return [
        (type(item).__name__, str(item)) if isinstance(item, igtl.MalformedMessage) else item
        for item in items
    ]


def feed_all(chunks: list[bytes]) -> tuple[list, str | None]:
    """What a reader gives for ``chunks`` fed in turn, and why the stream broke (or None)."""
    reader, items = igtl.StreamReader(), []
    for chunk in chunks:
        try:
            items += reader.feed(chunk)
        except igtl.StreamBroken as error:
            return outcome(items + list(error.messages)), str(error)
    return outcome(items), None


def test_messages_come_out_in_order_with_their_kinds_and_bodies():
    stream = good_messages()
    items, broken = feed_all([b"".join(stream)])
    assert broken is None
    assert [(item.header.kind, item.header.device) for item in items] == [
        ("TRANSFORM", "Registration"),
        ("STRING", "CMD_1"),
        ("POINT", ""),
        ("STATUS", "Slicer"),
        ("IMAGE", "CT"),
        ("GET_STATUS", ""),
    ]
    assert [item.body for item in items] == [data[58:] for data in stream]
    assert items[0].header.timestamp_s == pytest.approx(1.25)
    assert igtl.read_status(igtl.content(items[3])) == (1, 0, "OK", "fine")


def test_two_messages_in_one_chunk_give_two_messages():
    first, second = good_messages()[:2]
    items = igtl.StreamReader().feed(first + second)
    assert [item.header.kind for item in items] == ["TRANSFORM", "STRING"]
    assert igtl.read_string(igtl.content(items[1])) == "START"


def test_a_stream_split_at_any_byte_gives_the_same_messages():
    stream = b"".join(good_messages() + [MALFORMED["bad CRC"], MALFORMED["unknown encoding"]])
    stream += b"".join(good_messages()[:2]) + BROKEN["version 7"]
    whole = feed_all([stream])
    assert whole[1] is not None and len(whole[0]) == 10
    for cut in range(len(stream) + 1):
        assert feed_all([stream[:cut], stream[cut:]]) == whole, cut
    assert feed_all([stream[i : i + 1] for i in range(len(stream))]) == whole
    assert feed_all([stream[i : i + 57] for i in range(0, len(stream), 57)]) == whole


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_each_malformed_message_gives_one_malformed_and_the_stream_goes_on(case):
    good = good_messages()[0]
    items = igtl.StreamReader().feed(MALFORMED[case] + good)
    assert len(items) == 2
    assert type(items[0]) is igtl.MalformedMessage
    assert str(items[0]).startswith(SAYS[case]) and "\n" not in str(items[0])
    assert isinstance(items[1], igtl.Message) and items[1].header.device == "Registration"
    one_byte_at_a_time = [MALFORMED[case][i : i + 1] for i in range(len(MALFORMED[case]))]
    assert feed_all([*one_byte_at_a_time, good]) == (outcome(items), None)


def test_a_body_of_a_size_other_than_its_headers_is_malformed():
    header = igtl.read_header(frame(b"TRANSFORM", b"Tool", bytes(48))[:58])
    with pytest.raises(igtl.MalformedMessage, match="body of 47 bytes; the header claims 48"):
        igtl.check_body(header, bytes(47))


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_header_that_is_not_sound_breaks_the_stream(case):
    good = good_messages()[1]
    reader = igtl.StreamReader()
    with pytest.raises(igtl.StreamBroken) as error:
        reader.feed(good + BROKEN[case] + good)
    assert isinstance(error.value, igtl.MalformedMessage)
    assert str(error.value).startswith("stream broken: ") and "\n" not in str(error.value)
    assert [message.header.device for message in error.value.messages] == ["CMD_1"]
    with pytest.raises(igtl.StreamBroken) as again:
        reader.feed(good)
    assert str(again.value) == str(error.value) and again.value.messages == ()


def test_the_reader_holds_at_most_a_header_and_the_largest_body():
    body = np.random.default_rng(7).bytes(igtl.MAX_BODY_BYTES)
    data = frame(b"IMAGE", b"CT", body)
    reader = igtl.StreamReader()
    chunk_bytes = 1000
    last = len(data) - chunk_bytes  # the last chunk completes the message
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        for offset in range(0, last, chunk_bytes):
            assert reader.feed(data[offset : min(offset + chunk_bytes, last)]) == []
        held = tracemalloc.get_traced_memory()[0] - start
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    bound = igtl.HEADER_BYTES + igtl.MAX_BODY_BYTES
    assert igtl.MAX_BODY_BYTES <= held and peak <= bound + 4 * chunk_bytes, (held, peak)
    (message,) = reader.feed(data[last:])
    assert message.header.kind == "IMAGE" and message.body == body
