"""The OpenIGTLink server alone: a client that reads too slowly loses the oldest droppable
frames and then, if it still cannot keep up, its connection, while the others go on; a
client past the limit is refused; a flooding client is read at its budget only; the
commands parse as documented."""

from __future__ import annotations

import socket
import time

import pyigtl
import pytest
from igtl_peer import Peer

from spm_opt.navigation import commands, igtl, server
from spm_opt.navigation.server import NavigationServer


def _wait(condition, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.01)


@pytest.fixture
def small_queues(monkeypatch):
    monkeypatch.setattr(server, "MAX_QUEUED_BYTES", 64 << 10)


def _pose(number: int) -> bytes:
    return igtl.pack("STRING", "Pose", igtl.string_body("x" * 10_000), float(number))


def test_a_client_that_does_not_read_loses_old_poses_not_the_others(small_queues):
    received = []
    with NavigationServer(lambda c, m: received.append(m), port=0) as link:
        idle = socket.create_connection(("127.0.0.1", link.port))
        idle.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        reader = Peer(link.port)
        _wait(lambda: link.clients == 2)
        for number in range(3000):  # 30 MB of droppable frames
            link.send(_pose(number), droppable=True)
        # the newest pose always arrives; older ones a queue could not hold are gone
        _wait(lambda: any(m.timestamp_s == 2999.0 for m in reader.of("Pose")))
        assert link.counts.frames_dropped > 0
        assert link.clients == 2  # dropping poses kept the idle client
        # frames that may not be dropped, 10 MB/s, which the reader keeps up with: once the
        # idle client's socket buffers are full, its queue overflows and it goes
        for number in range(3000):
            link.send(_pose(number))
            time.sleep(0.001)
            if link.clients == 1:
                break
        _wait(lambda: link.clients == 1)
        assert link.counts.slow_clients_closed == 1
        reader.send(pyigtl.StringMessage("hello", device_name="Note"))
        _wait(lambda: received)
        assert received[0].header.device == "Note"
        reader.close()
        idle.close()


def test_a_client_past_the_limit_is_refused():
    with NavigationServer(lambda c, m: None, port=0) as link:
        clients = [
            socket.create_connection(("127.0.0.1", link.port)) for _ in range(server.MAX_CLIENTS)
        ]
        _wait(lambda: link.clients == server.MAX_CLIENTS)
        extra = socket.create_connection(("127.0.0.1", link.port))
        extra.settimeout(5.0)
        assert extra.recv(1) == b""  # closed at once
        _wait(lambda: link.counts.refused == 1)
        for client in [*clients, extra]:
            client.close()


def test_a_flooding_client_is_read_at_its_budget():
    with NavigationServer(lambda c, m: None, port=0) as link:
        flood = igtl.pack("FOOBAR", "x", b"\0" * 60_000, 0.0)
        sent = 0
        with socket.create_connection(("127.0.0.1", link.port)) as client:
            client.settimeout(0.05)
            start = time.monotonic()
            while time.monotonic() - start < 1.5:
                try:
                    sent += client.send(flood)
                except TimeoutError:
                    continue
            elapsed = time.monotonic() - start
        read = link.counts.unknown_kinds * len(flood)
        allowed = server.READ_BURST_BYTES + server.READ_BYTES_PER_S * elapsed + len(flood)
        assert sent > allowed  # it sent more than the budget...
        assert read <= allowed  # ...and the server read no more than it


@pytest.mark.parametrize(
    "text, expected",
    [
        ("STOP", commands.Command("STOP")),
        ("  hold ", commands.Command("HOLD")),
        ("Resume", commands.Command("RESUME")),
        ("PLAN", commands.Command("PLAN", commands.DEFAULT_PLANNER)),
        ("plan ocp-min-time", commands.Command("PLAN", "ocp-min-time")),
    ],
)
def test_commands_parse(text, expected):
    assert commands.parse_command(text) == expected


@pytest.mark.parametrize(
    "text, code",
    [
        ("START", commands.ACCESS_DENIED),
        ("move_to_target", commands.ACCESS_DENIED),
        ("FLY", commands.UNKNOWN_INSTRUCTION),
        ("", commands.UNKNOWN_INSTRUCTION),
        ("PLAN warp-drive", commands.UNKNOWN_INSTRUCTION),
        ("STOP now", commands.UNKNOWN_INSTRUCTION),
        ("STOP" + " " * 300, commands.UNKNOWN_INSTRUCTION),
    ],
)
def test_commands_refused_say_why(text, code):
    reply = commands.parse_command(text)
    assert isinstance(reply, commands.CommandReply) and reply.code == code
    assert reply.message and len(reply.name) <= 20
