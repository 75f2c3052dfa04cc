"""Streamed answers of the bounded edge (server-sent events for `robotconf ui`) keep its bounds, on
real sockets: chunks arrive as they are made, a stream ends when the server ends it, a client that
does not read is cut, a client that leaves ends its stream, and the connection caps still hold."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

from robotconf.readmodel.http_edge import BoundedHTTPServer, FedStream, Limits, Request, Response
from tests.integration.reconciler.test_listeners import closed_by_server, connect_from
from tests.support.watch import wait_for


class Streams:
    """A service answering every GET with a stream the test feeds."""

    def __init__(self) -> None:
        self.open: list[FedStream] = []
        self.closed = 0
        self._lock = threading.Lock()

    def answer(self, request: Request) -> Response:
        if request.target == "/plain":
            return Response.text(200, "plain")
        stream = FedStream(backlog=1000, on_close=self._closed)
        with self._lock:
            self.open.append(stream)
        return Response(200, b": hello\n\n", "text/event-stream", stream=stream, keepalive=b":\n\n")

    def refused(self, request: Request, code: int, message: str) -> Response:
        return Response.text(code, message)

    def _closed(self) -> None:
        with self._lock:
            self.closed += 1


@contextlib.contextmanager
def edge(limits: Limits) -> Iterator[tuple[BoundedHTTPServer, Streams]]:
    service = Streams()
    server = BoundedHTTPServer("stream-test", service, limits)
    server.listen("127.0.0.1", 0)
    try:
        yield server, service
    finally:
        server.close()


def open_stream(port: int, source: str = "127.0.0.1") -> socket.socket:
    sock = connect_from(source, port)
    sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
    return sock


def read_until(sock: socket.socket, wanted: bytes) -> bytes:
    sock.settimeout(20)
    got = b""
    while wanted not in got:
        data = sock.recv(65536)
        assert data, f"closed before {wanted!r}: {got!r}"
        got += data
    return got


def read_to_end(sock: socket.socket) -> bytes:
    sock.settimeout(20)
    got = b""
    while data := sock.recv(65536):
        got += data
    return got


def test_chunks_arrive_as_made_and_the_stream_ends_when_the_server_ends_it() -> None:
    with edge(Limits()) as (server, service):
        sock = open_stream(server.port)
        head = read_until(sock, b": hello\n\n")
        assert head.startswith(b"HTTP/1.1 200 ")
        assert b"Content-Length" not in head and b"text/event-stream" in head
        stream = wait_for(lambda: service.open[0] if service.open else None, "a stream")
        stream.put(b"data: one\n\n")
        read_until(sock, b"data: one\n\n")
        stream.put(b"data: two\n\n")
        stream.end()
        assert read_to_end(sock).endswith(b"data: two\n\n")
        wait_for(lambda: service.closed == 1 or None, "the stream closed")
        wait_for(lambda: server.open_connections == 0 or None, "the connection forgotten")
        sock.close()


def test_an_idle_stream_gets_its_keepalive() -> None:
    with edge(Limits(stream_idle=0.2)) as (server, _):
        sock = open_stream(server.port)
        read_until(sock, b": hello\n\n:\n\n")
        sock.close()


def test_a_client_that_does_not_read_is_cut_and_its_stream_closed() -> None:
    with edge(Limits(stream_buffer=64 * 1024, stream_drain=1.0)) as (server, service):
        sock = connect_from("127.0.0.1", server.port)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
        stream = wait_for(lambda: service.open[0] if service.open else None, "a stream")
        chunk = b"data: " + b"x" * 16 * 1024 + b"\n\n"

        def feed() -> bool | None:
            if stream.closed:
                return True
            for _ in range(20):
                stream.put(chunk)
            return None

        wait_for(feed, "the stream closed for a client that reads nothing")
        wait_for(lambda: server.open_connections == 0 or None, "the connection cut")
        assert service.closed == 1
        sock.close()


def test_a_client_that_leaves_ends_its_stream() -> None:
    with edge(Limits()) as (server, service):
        sock = open_stream(server.port)
        read_until(sock, b": hello\n\n")
        sock.close()
        wait_for(lambda: service.closed == 1 or None, "the stream closed")
        wait_for(lambda: server.open_connections == 0 or None, "the connection forgotten")


def test_streams_count_against_the_caps_and_end_when_the_server_closes() -> None:
    limits = Limits(connections=64, per_client=3)
    with edge(limits) as (server, service):
        streams = [open_stream(server.port) for _ in range(3)]
        for sock in streams:
            read_until(sock, b": hello\n\n")
        refused = open_stream(server.port)
        wait_for(lambda: closed_by_server(refused) or None, "the fourth stream refused")
        other = connect_from("127.0.0.3", server.port)  # another address still gets in
        other.sendall(b"GET /plain HTTP/1.1\r\nHost: x\r\n\r\n")
        assert read_to_end(other).endswith(b"plain\n")
        server.close()
        for sock in streams:
            read_to_end(sock)  # ends: the server closed it
            sock.close()
        assert service.closed == 3
        refused.close()
        other.close()
