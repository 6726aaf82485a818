"""An OpenIGTLink server on a thread of its own: it accepts clients (3D Slicer's
OpenIGTLinkIF, PLUS, a script), frames what they send and hands each sound message to a
callback, and sends what it is given to every client.

Nothing here waits on a client. Sockets are non-blocking and served by one selector loop;
what is sent is queued per client, at most :data:`MAX_QUEUED_BYTES`. A client that reads
too slowly loses the oldest frames marked droppable (the tool's pose: the next one
replaces it); a client that still cannot keep up is closed. A malformed message is
dropped with one log line (see :mod:`spm_opt.navigation.igtl`); a stream that can no
longer be framed closes its client only. The server installs no signal handlers, so
Ctrl-C and SIGTERM keep the meaning the executor gives them.
"""

from __future__ import annotations

import collections
import errno
import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from spm_opt.base.errors import CommunicationError
from spm_opt.navigation.igtl import (
    HEADER_BYTES,
    KINDS_RECEIVED,
    MAX_BODY_BYTES,
    MalformedMessage,
    Message,
    StreamBroken,
    StreamReader,
)

_LOG = logging.getLogger(__name__)

DEFAULT_PORT = 18944
"""3D Slicer's OpenIGTLinkIF default port."""
MAX_CLIENTS = 8
"""Clients served at once; one more is refused (closed at once)."""
MAX_QUEUED_BYTES = 8 << 20
"""Bytes queued for one client before its oldest droppable frames go, bytes (8 MiB)."""
RECEIVE_BYTES = 1 << 16
"""Bytes read from a client at a time, at most."""
READ_BYTES_PER_S = 64 << 10
"""What the server reads of one client per second at most, bytes/s (64 KiB/s; a burst of
:data:`READ_BURST_BYTES` first). A flap, a registration and commands are a few hundred
bytes; the bound keeps a flooding client from holding the server's thread, and the
interpreter lock the control loop shares with it: beyond it the client waits (TCP holds
what it sends)."""
READ_BURST_BYTES = HEADER_BYTES + MAX_BODY_BYTES
"""The most a client may send at once before :data:`READ_BYTES_PER_S` applies, bytes."""
READ_RESUME_BYTES = 16 << 10
"""A client whose budget is spent is read again once it has refilled this far, bytes (a
quarter of a second at :data:`READ_BYTES_PER_S`): reading it a byte at a time as its
budget trickles back would keep the server's thread spinning."""
FLUSH_S = 1.0
"""How long closing goes on sending what is queued (the run's last state), s."""
SELECT_TIMEOUT_S = 0.05
"""Longest wait of the selector loop, s (a send or close wakes it at once)."""

OnMessage = Callable[[int, Message], None]
OnConnect = Callable[[int], None]


@dataclass
class ServerCounts:
    """What the server did since it started (for logs, tests and the closing summary)."""

    connections: int = 0
    refused: int = 0
    messages_received: int = 0
    malformed: int = 0
    unknown_kinds: int = 0
    broken_streams: int = 0
    frames_sent: int = 0
    frames_dropped: int = 0
    slow_clients_closed: int = 0
    handler_errors: int = 0


@dataclass
class _Client:
    number: int
    sock: socket.socket
    address: str
    reader: StreamReader = field(default_factory=StreamReader)
    queue: collections.deque[tuple[bytes, bool]] = field(default_factory=collections.deque)
    queued_bytes: int = 0
    sent_of_first: int = 0  # bytes of the queue's first frame already sent
    too_slow: bool = False  # over the bound with nothing left to drop: closed next round
    watched: int = 0  # the selector events it is registered for (0: not registered)
    budget: float = float(READ_BURST_BYTES)  # bytes it may send now
    budget_at: float = field(default_factory=time.monotonic)  # when the budget was counted

    def refill(self) -> float:
        """The bytes it may send now, :data:`READ_BYTES_PER_S` since the last count."""
        now = time.monotonic()
        self.budget = min(READ_BURST_BYTES, self.budget + (now - self.budget_at) * READ_BYTES_PER_S)
        self.budget_at = now
        return self.budget


class NavigationServer:
    """An OpenIGTLink server (see the module's docstring).

    Parameters
    ----------
    on_message : callable
        Called on the server's thread with (client number, message) for each sound message
        of a kind in :data:`~spm_opt.navigation.igtl.KINDS_RECEIVED`; it must not block.
        An exception it raises is logged and the server goes on.
    on_connect : callable, optional
        Called on the server's thread with a new client's number, to send it what a client
        needs first (the models).
    host : str
        The address to listen on (127.0.0.1: this machine only).
    port : int
        The TCP port (0: any free one; :attr:`port` says which).
    """

    def __init__(
        self,
        on_message: OnMessage,
        on_connect: OnConnect | None = None,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
    ) -> None:
        self._on_message = on_message
        self._on_connect = on_connect or (lambda _client: None)
        self._host, self._requested_port = host, port
        self.counts = ServerCounts()
        self._clients: dict[int, _Client] = {}
        self._lock = threading.Lock()  # guards the clients' queues
        self._selector = selectors.DefaultSelector()
        self._listener: socket.socket | None = None
        self._wake_read, self._wake_write = socket.socketpair()
        self._thread: threading.Thread | None = None
        self._closing = threading.Event()
        self._close_by = 0.0  # until when closing sends what is queued (time.monotonic())
        self._next_number = 1

    # ------------------------------------------------------------------ the owner's side
    def start(self) -> None:
        """Listen and serve on a daemon thread.

        Raises
        ------
        CommunicationError
            The address cannot be listened on (the port is taken, the host is not this
            machine's).
        """
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            listener.bind((self._host, self._requested_port))
            listener.listen(MAX_CLIENTS)
        except OSError as error:
            listener.close()
            reason = "the port is taken" if error.errno == errno.EADDRINUSE else error.strerror
            raise CommunicationError(
                f"OpenIGTLink server on {self._host}:{self._requested_port}: {reason} "
                "(--igtl takes another port, --igtl-host another address)"
            ) from None
        listener.setblocking(False)
        self._listener = listener
        self._wake_read.setblocking(False)
        self._selector.register(listener, selectors.EVENT_READ, "listener")
        self._selector.register(self._wake_read, selectors.EVENT_READ, "wake")
        self._thread = threading.Thread(target=self._serve, name="igtl-server", daemon=True)
        self._thread.start()
        _LOG.info("OpenIGTLink server listening on %s:%d", self._host, self.port)

    @property
    def port(self) -> int:
        """The TCP port listened on."""
        if self._listener is None:
            return self._requested_port
        return int(self._listener.getsockname()[1])

    @property
    def clients(self) -> int:
        """Clients connected now."""
        with self._lock:
            return len(self._clients)

    def send(self, frame: bytes, droppable: bool = False, client: int | None = None) -> None:
        """Queue one packed message for every client (or one, by number); never blocks.

        ``droppable``: a frame the next one replaces (a pose), which a slow client may lose.
        """
        with self._lock:
            targets = (
                list(self._clients.values())
                if client is None
                else [c for c in (self._clients.get(client),) if c is not None]
            )
            for target in targets:
                target.queue.append((frame, droppable))
                target.queued_bytes += len(frame)
                self._bound(target)
        if targets:
            self._wake()

    def close(self) -> None:
        """Send what is queued (for at most :data:`FLUSH_S`), close every client and stop
        listening; waits for the server's thread."""
        self._close_by = time.monotonic() + FLUSH_S
        self._closing.set()
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for sock in (self._wake_read, self._wake_write):
            sock.close()

    def __enter__(self) -> NavigationServer:
        self.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the server thread
    def _wake(self) -> None:
        try:
            self._wake_write.send(b"\0")
        except (BlockingIOError, OSError):
            pass  # a wake-up is pending already, or the server is closing

    def _bound(self, client: _Client) -> None:
        """Drop the oldest droppable frames past :data:`MAX_QUEUED_BYTES` (the lock held);
        a frame half sent stays."""
        if client.queued_bytes <= MAX_QUEUED_BYTES:
            return
        kept: collections.deque[tuple[bytes, bool]] = collections.deque()
        for index, (frame, droppable) in enumerate(client.queue):
            started = index == 0 and client.sent_of_first > 0
            if client.queued_bytes > MAX_QUEUED_BYTES and droppable and not started:
                client.queued_bytes -= len(frame)
                self.counts.frames_dropped += 1
            else:
                kept.append((frame, droppable))
        client.queue = kept
        client.too_slow = client.queued_bytes > MAX_QUEUED_BYTES

    def _serve(self) -> None:
        try:
            while not self._closing.is_set() or self._flushing():
                for key, events in self._selector.select(SELECT_TIMEOUT_S):
                    if key.data == "listener":
                        self._accept()
                    elif key.data == "wake":
                        self._drain_wake()
                    else:
                        self._serve_client(key.data, events)
                self._watch_clients()
        except Exception:  # the link must never take the program down
            _LOG.exception("OpenIGTLink server stopped by an error")
        finally:
            for client in list(self._clients.values()):
                self._drop(client, "server closed")
            if self._listener is not None:
                self._selector.unregister(self._listener)
                self._listener.close()
            self._selector.close()

    def _flushing(self) -> bool:
        """Closing, but frames are still queued and :data:`FLUSH_S` has not passed."""
        with self._lock:
            queued = any(client.queue for client in self._clients.values())
        return queued and time.monotonic() < self._close_by

    def _drain_wake(self) -> None:
        try:
            while self._wake_read.recv(4096):
                pass
        except BlockingIOError:
            pass

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            sock, address = self._listener.accept()
        except BlockingIOError:
            return
        where = f"{address[0]}:{address[1]}"
        if self.clients >= MAX_CLIENTS:
            self.counts.refused += 1
            _LOG.warning("OpenIGTLink client %s refused: %d clients already", where, MAX_CLIENTS)
            sock.close()
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(self._next_number, sock, where)
        self._next_number += 1
        with self._lock:
            self._clients[client.number] = client
        self._selector.register(sock, selectors.EVENT_READ, client)
        client.watched = selectors.EVENT_READ
        self.counts.connections += 1
        _LOG.info("OpenIGTLink client %d connected from %s", client.number, where)
        self._call(self._on_connect, client.number)

    def _serve_client(self, client: _Client, events: int) -> None:
        if events & selectors.EVENT_READ and not self._receive(client):
            return
        if events & selectors.EVENT_WRITE:
            self._transmit(client)

    def _receive(self, client: _Client) -> bool:
        """Read what the client sent and hand on its messages; False if it is gone."""
        allowed = int(client.refill())
        if allowed < 1:
            return True  # its budget is spent: read again when it has refilled
        try:
            data = client.sock.recv(min(RECEIVE_BYTES, allowed))
        except BlockingIOError:
            return True
        except OSError as error:
            self._drop(client, f"receive failed: {error}")
            return False
        if not data:
            self._drop(client, "disconnected")
            return False
        client.budget -= len(data)
        try:
            items = client.reader.feed(data)
        except StreamBroken as error:
            self.counts.broken_streams += 1
            self._drop(client, f"its stream cannot be framed: {error}")
            return False
        for item in items:
            if isinstance(item, MalformedMessage):
                self.counts.malformed += 1
                _LOG.warning("OpenIGTLink client %d: message dropped: %s", client.number, item)
            elif item.header.kind not in KINDS_RECEIVED:
                self.counts.unknown_kinds += 1
                _LOG.warning(
                    "OpenIGTLink client %d: %s message %r dropped: not a kind read here (%s)",
                    client.number,
                    item.header.kind,
                    item.header.device,
                    ", ".join(KINDS_RECEIVED),
                )
            else:
                self.counts.messages_received += 1
                self._call(self._on_message, client.number, item)
        return True

    def _call(self, handler: Callable[..., None], *arguments: object) -> None:
        try:
            handler(*arguments)
        except Exception:
            self.counts.handler_errors += 1
            _LOG.exception("OpenIGTLink handler failed; the link goes on")

    def _watch_clients(self) -> None:
        """Close the clients too slow to keep up; watch each of the others for what it
        needs now: reading while its budget lasts, writing while frames are queued."""
        with self._lock:
            clients = list(self._clients.values())
        for client in clients:
            if client.too_slow:
                self.counts.slow_clients_closed += 1
                self._drop(client, "it reads too slowly to keep up")
                continue
            threshold = 1.0 if client.watched & selectors.EVENT_READ else READ_RESUME_BYTES
            reading = selectors.EVENT_READ if client.refill() >= threshold else 0
            wanted = reading | (selectors.EVENT_WRITE if client.queue else 0)
            if wanted == client.watched:
                continue
            if client.watched == 0:
                self._selector.register(client.sock, wanted, client)
            elif wanted == 0:
                self._selector.unregister(client.sock)
            else:
                self._selector.modify(client.sock, wanted, client)
            client.watched = wanted

    def _transmit(self, client: _Client) -> None:
        """Send as much of the client's queue as its socket takes now."""
        while True:
            with self._lock:
                if not client.queue:
                    return
                frame = client.queue[0][0]
                offset = client.sent_of_first
            try:
                sent = client.sock.send(memoryview(frame)[offset:])
            except BlockingIOError:
                return
            except OSError as error:
                self._drop(client, f"send failed: {error}")
                return
            with self._lock:
                client.sent_of_first += sent
                if client.sent_of_first < len(frame):
                    return
                client.queue.popleft()
                client.queued_bytes -= len(frame)
                client.sent_of_first = 0
                self.counts.frames_sent += 1

    def _drop(self, client: _Client, why: str) -> None:
        with self._lock:
            if self._clients.pop(client.number, None) is None:
                return
        if client.watched:
            self._selector.unregister(client.sock)
            client.watched = 0
        client.sock.close()
        _LOG.info("OpenIGTLink client %d (%s) closed: %s", client.number, client.address, why)
