"""Hostile and broken clients during a run: each of 24 kinds of malformed message is
dropped with one log line, the link answers the next client, the run is untouched and the
server's memory stays bounded. The messages are built here with ``struct`` and pyigtl,
not with the server's codec."""

from __future__ import annotations

import logging
import resource
import socket
import struct
import time

import crcmod
import numpy as np
import pyigtl
import pytest
from igtl_peer import Peer
from navigation_helpers import SimulatedRun

_ECMA = crcmod.mkCrcFun(0x142F0E1EBA9EA3693, initCrc=0, rev=False, xorOut=0)


def header(
    kind: bytes,
    device: bytes,
    body: bytes,
    size: int | None = None,
    crc: int | None = None,
    version: int = 1,
) -> bytes:
    """A header laid out by header.md, with any field wrong on purpose."""
    return struct.pack(
        ">H12s20sIIQQ",
        version,
        kind,
        device,
        0,
        0,
        len(body) if size is None else size,
        _ECMA(body) if crc is None else crc,
    )


def message(kind: bytes, device: bytes, body: bytes, **wrong) -> bytes:
    return header(kind, device, body, **wrong) + body


def string_body(text: bytes, encoding: int = 3, length: int | None = None) -> bytes:
    return struct.pack(">HH", encoding, len(text) if length is None else length) + text


def point_body(x: float) -> bytes:
    return struct.pack(">64s32s4B4f20s", b"P1", b"", 255, 0, 0, 255, x, 0.0, 0.0, 1.0, b"")


TRANSFORM = struct.pack(">12f", 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0)

# (what, bytes, the stream can go on after it)
HOSTILE = [
    ("a bad CRC", message(b"TRANSFORM", b"RASToRobot", TRANSFORM, crc=1), True),
    ("a TRANSFORM of 44 bytes", message(b"TRANSFORM", b"RASToRobot", TRANSFORM[:44]), True),
    (
        "a body size that lies short",
        header(b"TRANSFORM", b"RASToRobot", TRANSFORM, size=20) + TRANSFORM,
        False,
    ),
    ("a body size that lies long", header(b"STRING", b"CMD_1", b"", size=5000) + b"STOP", False),
    ("a claimed body of 2**63 bytes", header(b"STRING", b"CMD_1", b"", size=2**63), False),
    (
        "a claimed body just over the bound",
        header(b"POINT", b"Flap", b"", size=(1 << 20) + 1),
        False,
    ),
    ("an unknown type", message(b"FOOBAR", b"x", b"\0" * 64), True),
    (
        "a device name that is not ASCII",
        message(b"STRING", "Gerät".encode("latin-1"), string_body(b"STOP")),
        False,
    ),
    ("a TYPE of control characters", message(b"\x01\x02", b"x", b""), False),
    ("version 99", message(b"STRING", b"CMD_1", string_body(b"STOP"), version=99), False),
    ("an empty TYPE", message(b"", b"CMD_1", string_body(b"STOP")), False),
    (
        "a STRING of an unknown encoding",
        message(b"STRING", b"CMD_1", string_body(b"STOP", encoding=9999)),
        True,
    ),
    (
        "a STRING longer than its body",
        message(b"STRING", b"CMD_1", string_body(b"STOP", length=900)),
        True,
    ),
    (
        "a STRING of bytes that are not UTF-8",
        message(b"STRING", b"CMD_1", string_body(b"\xff\xfe", encoding=106)),
        True,
    ),
    ("a POINT at NaN", message(b"POINT", b"Flap", point_body(float("nan"))), True),
    ("a POINT body of 100 bytes", message(b"POINT", b"Flap", b"\0" * 100), True),
    (
        "a TRANSFORM of NaN",
        message(b"TRANSFORM", b"RASToRobot", struct.pack(">12f", *[float("nan")] * 12)),
        True,
    ),
    (
        "a registration that is not rigid",
        message(
            b"TRANSFORM", b"RASToRobot", struct.pack(">12f", 2, 0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0)
        ),
        True,
    ),
    (
        "a command of 10,000 characters",
        message(b"STRING", b"CMD_7", string_body(b"A" * 10_000)),
        True,
    ),
    ("a command to start", message(b"STRING", b"CMD_8", string_body(b"START")), True),
    ("a header and no more", header(b"STRING", b"CMD_1", string_body(b"STOP"))[:30], False),
    ("64 KiB of random bytes", np.random.default_rng(3).bytes(1 << 16), False),
    (
        "a version 2 body whose sizes do not fit",
        message(
            b"STRING",
            b"CMD_1",
            struct.pack(">HHII", 12, 40, 4000, 1) + string_body(b"STOP"),
            version=2,
        ),
        True,
    ),
    (
        "a STATUS and a POLYDATA, kinds a robot only sends",
        message(b"STATUS", b"x", struct.pack(">Hq20s", 1, 0, b"OK") + b"\0")
        + message(b"POLYDATA", b"x", b"\0" * 40),
        True,
    ),
]


def _alive(port: int, number: int) -> None:
    """A new client's command is answered: the server goes on."""
    peer = Peer(port)
    try:
        peer.send(pyigtl.StringMessage("PING", device_name=f"CMD_ping{number}"))
        reply = peer.wait_for(lambda m: m.device == f"CMD_ping{number}", timeout_s=10.0)
        assert reply.content[0] == 12  # unknown instruction, answered
    finally:
        peer.close()


def test_the_kinds_are_at_least_twenty():
    assert len(HOSTILE) >= 20


@pytest.mark.real_time
def test_hostile_messages_leave_the_run_and_the_link_alone(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="spm_opt.navigation")
    with SimulatedRun(tmp_path) as run:
        port = run.link.server.port
        watcher = Peer(port)
        watcher.wait_for(lambda m: m.device == "RunState")
        run.start()
        watcher.wait_for(lambda m: m.device == "RunState" and m.content[1] == "running")
        before_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        for number, (what, data, _goes_on) in enumerate(HOSTILE):
            lines_before = len(caplog.records)
            with socket.create_connection(("127.0.0.1", port)) as hostile:
                hostile.sendall(data)
                hostile.shutdown(socket.SHUT_WR)
                hostile.settimeout(5.0)
                while hostile.recv(65536):  # until the server closes it
                    pass
            _alive(port, number)
            said = [r.getMessage() for r in caplog.records[lines_before:]]
            assert any("dropped" in line or "closed" in line or "CMD_" in line for line in said), (
                what
            )
        # a flood: bodies at the bound, each with a bad CRC, for 2 s, as fast as TCP takes
        flood = message(b"POINT", b"Flap", b"\0" * (136 * 722), crc=1)
        flooded = 0
        with socket.create_connection(("127.0.0.1", port)) as hostile:
            hostile.settimeout(0.1)
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                try:
                    flooded += hostile.send(flood)
                except TimeoutError:
                    continue
        _alive(port, len(HOSTILE))
        grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before_kb) / 1024
        watcher.wait_for(lambda m: m.device == "RunState" and m.content[1] in ("at rest", "fault"))
        watcher.close()
    result = run.result
    assert result is not None and result.succeeded, result.reason
    assert result.feed_events == [] and result.signals == []
    assert np.array_equal(run.link.image_to_robot, run.link.problem.skull.image_to_robot_mm)
    assert run.link.flap is None
    counts = run.link.server.counts
    assert counts.malformed >= 10 and counts.broken_streams >= 6 and counts.unknown_kinds >= 2
    assert counts.handler_errors == 0
    assert flooded > 100_000
    assert grown_mb < 20.0, f"the process grew {grown_mb:.1f} MB under {flooded:,} flooded bytes"
