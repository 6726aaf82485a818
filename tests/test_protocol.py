"""The Protocol 2.0 codec against the reference's worked examples, and its properties."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from spm_opt.execution.protocol import (
    HEADER,
    Instruction,
    PacketReader,
    build_instruction,
    build_status,
    crc16,
    layout_consistent,
    stuff,
    unstuff,
)

PING_1 = bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")
PING_REPLY_1 = bytes.fromhex("FF FF FD 00 01 07 00 55 00 08 95 00 60 BB")
READ_611_1 = bytes.fromhex("FF FF FD 00 01 07 00 02 63 02 04 00 1B F9")
TORQUE_ON_1 = bytes.fromhex("FF FF FD 00 01 06 00 03 32 02 01 30 EC")

# bytes that make stuffing patterns likely
pattern_bytes = st.lists(st.sampled_from([0xFF, 0xFD, 0x00, 0x01, 0x55]), max_size=40).map(bytes)
any_bytes = st.one_of(pattern_bytes, st.binary(max_size=40))


def crc16_bitwise(data: bytes) -> int:
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def unstuffed_frame(device_id: int, instruction: int, params: bytes) -> bytes:
    """A packet as dynamixel-sdk 4.1.0 sends it: never stuffed, LEN of the raw params."""
    body = bytes((instruction,)) + params
    length = len(body) + 2
    packet = HEADER + bytes((device_id, length & 0xFF, length >> 8)) + body
    crc = crc16(packet)
    return packet + bytes((crc & 0xFF, crc >> 8))


# ------------------------------------------------------------------------------- CRC
def test_crc_check_value():
    assert crc16(b"123456789") == 0xFEE8


@given(any_bytes)
def test_crc_matches_the_bitwise_definition(data):
    assert crc16(data) == crc16_bitwise(data)


@given(any_bytes, any_bytes)
def test_crc_continues_a_running_value(a, b):
    assert crc16(b, crc16(a)) == crc16(a + b)


@given(any_bytes)
def test_crc_of_data_followed_by_its_crc_big_endian_is_zero(data):
    assert crc16(data + crc16(data).to_bytes(2, "big")) == 0


# ------------------------------------------------------------------- worked examples
def test_builds_the_reference_examples():
    assert build_instruction(1, Instruction.PING) == PING_1
    assert build_status(1, 0, bytes.fromhex("08 95 00")) == PING_REPLY_1
    assert build_instruction(1, Instruction.READ, bytes.fromhex("63 02 04 00")) == READ_611_1
    assert build_instruction(1, Instruction.WRITE, bytes.fromhex("32 02 01")) == TORQUE_ON_1


def test_parses_the_reference_examples():
    packets = PacketReader().feed(PING_1 + PING_REPLY_1 + READ_611_1 + TORQUE_ON_1)
    assert [(p.id, p.instruction, p.params, p.crc_ok) for p in packets] == [
        (1, Instruction.PING, b"", True),
        (1, Instruction.STATUS, bytes.fromhex("00 08 95 00"), True),
        (1, Instruction.READ, bytes.fromhex("63 02 04 00"), True),
        (1, Instruction.WRITE, bytes.fromhex("32 02 01"), True),
    ]
    reply = packets[1]
    assert reply.error == 0
    assert int.from_bytes(reply.data[:2], "little") == 38152


# ------------------------------------------------------------------------- stuffing
def test_stuffing_example():
    plain = bytes.fromhex("03 54 02 FF FF FD FF")  # write of goal position -131073
    stuffed = bytes.fromhex("03 54 02 FF FF FD FD FF")
    assert stuff(plain) == stuffed
    assert unstuff(stuffed) == plain


def test_unstuff_keeps_an_unstuffed_pattern():
    assert unstuff(bytes.fromhex("FF FF FD FF")) == bytes.fromhex("FF FF FD FF")
    assert unstuff(bytes.fromhex("00 FF FF FD")) == bytes.fromhex("00 FF FF FD")


@given(any_bytes)
def test_unstuff_undoes_stuff(data):
    assert unstuff(stuff(data)) == data


@given(any_bytes)
def test_stuffed_data_has_fd_after_every_pattern(data):
    stuffed = stuff(data)
    start = stuffed.find(b"\xff\xff\xfd")
    while start >= 0:
        assert stuffed[start + 3 : start + 4] == b"\xfd"
        start = stuffed.find(b"\xff\xff\xfd", start + 4)


@given(any_bytes)
def test_stuffing_adds_one_byte_per_pattern(data):
    assert len(stuff(data)) == len(data) + data.count(b"\xff\xff\xfd")


@given(st.integers(0, 252), any_bytes.filter(lambda p: len(p) >= 3))
def test_build_then_parse_gives_the_params(device_id, params):
    packets = PacketReader().feed(build_instruction(device_id, Instruction.WRITE, params))
    assert len(packets) == 1
    assert packets[0].id == device_id and packets[0].crc_ok
    assert packets[0].params == params


@given(st.integers(0, 252), st.integers(0, 0x7F), pattern_bytes)
def test_status_round_trip(device_id, error, data):
    (packet,) = PacketReader().feed(build_status(device_id, error, data))
    assert (packet.instruction, packet.error, packet.data) == (Instruction.STATUS, error, data)


# -------------------------------------------------- the SDK's unstuffed packets
def test_unstuffed_goal_position_minus_131073_is_read_by_its_length():
    data = (-131073).to_bytes(4, "little", signed=True)
    assert data == bytes.fromhex("FF FF FD FF")
    params = (596).to_bytes(2, "little") + data
    (packet,) = PacketReader().feed(unstuffed_frame(1, Instruction.WRITE, params))
    assert packet.crc_ok and packet.readings == (params,)


def test_unstuffed_sync_write_with_fd_fd_prefers_the_consistent_reading():
    # ids 1 and 2, 4 bytes at 596; id 1's data FF FF FD FD looks like stuffing
    params = bytes.fromhex("54 02 04 00 01 FF FF FD FD 02 10 00 00 00")
    (packet,) = PacketReader().feed(unstuffed_frame(0xFE, Instruction.SYNC_WRITE, params))
    assert packet.params == params
    assert packet.readings[1] == bytes.fromhex("54 02 04 00 01 FF FF FD 02 10 00 00 00")


def test_stuffed_sync_write_reads_the_standard_way():
    params = bytes.fromhex("54 02 04 00 01 FF FF FD FD 02 10 00 00 00")
    (packet,) = PacketReader().feed(build_instruction(0xFE, Instruction.SYNC_WRITE, params))
    assert packet.params == params


# ---------------------------------------------------------------------- the reader
def test_reader_resynchronises_after_garbage_and_split_input():
    stream = b"\x00\xff\xfd\xff\xff\x12" + PING_1 + b"\xff\xff" + READ_611_1
    reader = PacketReader()
    packets = []
    for byte in stream:
        packets += reader.feed(bytes((byte,)))
    assert [p.instruction for p in packets] == [Instruction.PING, Instruction.READ]
    assert reader.pending == 0


def test_reader_flags_a_bad_crc_and_continues():
    corrupt = PING_1[:-1] + bytes((PING_1[-1] ^ 1,))
    packets = PacketReader().feed(corrupt + READ_611_1)
    assert [(p.instruction, p.crc_ok) for p in packets] == [
        (Instruction.PING, False),
        (Instruction.READ, True),
    ]


def test_reader_skips_a_header_with_an_impossible_length():
    bogus = HEADER + bytes.fromhex("01 FF 7F")
    packets = PacketReader().feed(bogus + PING_1)
    assert [p.instruction for p in packets] == [Instruction.PING]


def test_reader_keeps_a_partial_header_and_can_reset():
    reader = PacketReader()
    assert reader.feed(PING_1[:3]) == []
    assert reader.pending == 3
    reader.reset()
    assert reader.pending == 0
    assert reader.feed(PING_1[3:]) == []


@given(
    st.binary(max_size=30).filter(lambda g: b"\xff" not in g),
    st.lists(st.integers(1, 9), min_size=1, max_size=30),
)
def test_reader_finds_a_packet_after_noise_in_any_chunking(noise, cuts):
    stream = noise + TORQUE_ON_1 + PING_REPLY_1
    reader = PacketReader()
    packets, position, k = [], 0, 0
    while position < len(stream):
        size = cuts[k % len(cuts)]
        packets += reader.feed(stream[position : position + size])
        position, k = position + size, k + 1
    assert [p.instruction for p in packets] == [Instruction.WRITE, Instruction.STATUS]


@pytest.mark.parametrize(
    ("instruction", "params", "ok"),
    [
        (Instruction.PING, b"", True),
        (Instruction.PING, b"\x00", False),
        (Instruction.READ, bytes(4), True),
        (Instruction.READ, bytes(5), False),
        (Instruction.WRITE, bytes(2), False),
        (Instruction.SYNC_READ, bytes.fromhex("63 02 0C 00 01 02"), True),
        (Instruction.SYNC_READ, bytes.fromhex("63 02 0C 00"), False),
        (Instruction.SYNC_WRITE, bytes.fromhex("54 02 04 00 01 00 00 00 00"), True),
        (Instruction.SYNC_WRITE, bytes.fromhex("54 02 04 00 01 00 00 00"), False),
        (Instruction.BULK_WRITE, bytes.fromhex("01 54 02 01 00 07"), True),
        (Instruction.BULK_WRITE, bytes.fromhex("01 54 02 02 00 07"), False),
        (0x7F, b"anything", True),
    ],
)
def test_layout_consistent(instruction, params, ok):
    assert layout_consistent(instruction, params) is ok
