"""A navigation client for the tests, built on pyigtl (an OpenIGTLink implementation nobody
here wrote): it frames the stream with pyigtl's header parser, unpacks TRANSFORM and
STRING with pyigtl's classes, and reads STATUS and POLYDATA, which pyigtl cannot, with
``struct`` from the protocol's documents (status.md, polydata.md).

Unlike pyigtl's own client, which keeps only the latest message of each device name, it
keeps every message with its arrival time, so a test can count rates and sequences.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyigtl

HEADER = pyigtl.MessageBase.IGTL_HEADER_SIZE


@dataclass(frozen=True)
class Received:
    """One message as the peer read it."""

    kind: str
    device: str
    timestamp_s: float
    arrived_s: float  # time.monotonic()
    content: Any  # (4, 4) matrix, str, (code, name, message) or (points, lines)


def read_status(body: bytes) -> tuple[int, str, str]:
    """STATUS: code uint16, subcode int64, error name char[20], message (NUL-terminated)."""
    code, _subcode, name = struct.unpack(">Hq20s", body[:30])
    return code, name.split(b"\0")[0].decode("ascii"), body[30:].split(b"\0")[0].decode()


def read_polydata(body: bytes) -> tuple[np.ndarray, list[list[int]]]:
    """POLYDATA (version 1): points (n, 3) float32 mm and the line cells."""
    counts = struct.unpack(">10I", body[:40])
    n_points, _n_vertices, size_vertices, n_lines, size_lines = counts[:5]
    offset = 40
    points = np.frombuffer(body, dtype=">f4", count=3 * n_points, offset=offset).reshape(-1, 3)
    offset += 12 * n_points + size_vertices
    cells = np.frombuffer(body, dtype=">u4", count=size_lines // 4, offset=offset)
    lines, at = [], 0
    for _ in range(n_lines):
        count = int(cells[at])
        lines.append([int(i) for i in cells[at + 1 : at + 1 + count]])
        at += 1 + count
    return points.astype(float), lines


class Peer:
    """Connects to ``port`` (retrying until it answers) and reads on a thread."""

    def __init__(self, port: int, host: str = "127.0.0.1", timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                self.sock = socket.create_connection((host, port), timeout=1.0)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        self.sock.settimeout(0.2)
        self.messages: list[Received] = []
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _exactly(self, size: int) -> bytes | None:
        data = b""
        while len(data) < size:
            if self._closed.is_set():
                return None
            try:
                chunk = self.sock.recv(size - len(data))
            except TimeoutError:
                continue
            except OSError:
                return None
            if not chunk:
                return None
            data += chunk
        return data

    def _read(self) -> None:
        while True:
            header = self._exactly(HEADER)
            if header is None:
                return
            fields = pyigtl.MessageBase.parse_header(header)
            body = self._exactly(fields["body_size"])
            if body is None:
                return
            kind, device = fields["message_type"], fields["device_name"]
            if kind in ("TRANSFORM", "STRING"):
                message = pyigtl.MessageBase.create_message(kind)
                message.unpack(fields, body)
                content = message.matrix if kind == "TRANSFORM" else message.string
            elif kind == "STATUS":
                content = read_status(body)
            elif kind == "POLYDATA":
                content = read_polydata(body)
            else:
                content = body
            # pyigtl gives the timestamp in seconds (fraction included)
            received = Received(kind, device, float(fields["timestamp"]), time.monotonic(), content)
            with self._lock:
                self.messages.append(received)

    def of(self, device: str, kind: str | None = None) -> list[Received]:
        """Every message of a device (and kind) received so far, in order."""
        with self._lock:
            return [
                m for m in self.messages if m.device == device and (kind is None or m.kind == kind)
            ]

    def received(self) -> int:
        """How many messages have been received so far (a mark for :meth:`wait_for`)."""
        with self._lock:
            return len(self.messages)

    def wait_for(self, predicate, timeout_s: float = 60.0, since: int = 0) -> Received:
        """The first message from the ``since``-th on that ``predicate`` holds for, waiting
        for it."""
        deadline = time.monotonic() + timeout_s
        seen = since
        while time.monotonic() < deadline:
            with self._lock:
                fresh = self.messages[seen:]
                seen = len(self.messages)
            for message in fresh:
                if predicate(message):
                    return message
            time.sleep(0.01)
        raise TimeoutError("no such message")

    def states(self) -> list[str]:
        """The RunState names received, repeats of the one before left out."""
        names = [m.content[1] for m in self.of("RunState", "STATUS")]
        return [n for i, n in enumerate(names) if i == 0 or n != names[i - 1]]

    def send(self, message: pyigtl.MessageBase) -> None:
        self.sock.sendall(message.pack())

    def send_raw(self, data: bytes) -> None:
        self.sock.sendall(data)

    def close(self) -> None:
        self._closed.set()
        try:
            self.sock.close()
        finally:
            self._thread.join(timeout=2.0)
