"""Real local HTTP receivers for alert tests: one that records and answers as told (200, 500,
a redirect), and one that answers a byte at a time (over TLS too, or its TLS handshake) and
notices when the client gives up."""

from __future__ import annotations

import contextlib
import json
import select
import socket
import ssl
import threading
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any


@dataclass(frozen=True)
class Request:
    method: str
    path: str
    headers: dict[str, str]
    body: Any  # the JSON body, parsed (None without one)


class Recorder:
    """An HTTP server on 127.0.0.1 that records every request and answers `status` (with
    `location` as its Location header when given: a redirect)."""

    def __init__(self, status: int = 200, location: str | None = None) -> None:
        self.status = status
        self.location = location
        self._requests: list[Request] = []
        self._lock = threading.Lock()
        recorder = self

        class Handler(BaseHTTPRequestHandler):
            def _record(self) -> None:
                length = int(self.headers.get("Content-Length", "0"))
                raw = self.rfile.read(length) if length else b""
                request = Request(
                    self.command,
                    self.path,
                    {k.lower(): v for k, v in self.headers.items()},
                    json.loads(raw) if raw else None,
                )
                with recorder._lock:
                    recorder._requests.append(request)
                self.send_response(recorder.status)
                if recorder.location is not None:
                    self.send_header("Location", recorder.location)
                self.send_header("Content-Length", "0")
                self.end_headers()

            do_POST = do_GET = do_HEAD = _record

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    @property
    def port(self) -> int:
        return int(self.server.server_address[1])

    @property
    def base(self) -> str:
        """The URL as logs and metrics name it: scheme, host and port."""
        return f"http://127.0.0.1:{self.port}"

    def requests(self) -> list[Request]:
        with self._lock:
            return list(self._requests)

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


ANSWER = b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"


class Dripper:
    """Reads each request whole, then answers 200 one byte every `every` seconds: each read of
    the client is quick, the answer takes len(ANSWER) * every seconds. Records, per request,
    how many bytes of the answer went out before the client went away (`given_up`), or that
    all did (`answered`). With `tls`, over TLS; with `handshake` too, it is the server's part
    of the TLS handshake that goes out a byte at a time (no request is ever read)."""

    def __init__(
        self, every: float, tls: ssl.SSLContext | None = None, handshake: bool = False
    ) -> None:
        self.every = every
        self.tls = tls
        self.handshake = handshake
        self.listener = socket.create_server(("127.0.0.1", 0))
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self.received = 0
        self.given_up: list[int] = []
        self.answered = 0
        threading.Thread(target=self._serve, daemon=True).start()

    @property
    def url(self) -> str:
        scheme = "https" if self.tls is not None else "http"
        return f"{scheme}://127.0.0.1:{self.listener.getsockname()[1]}/hook"

    def _serve(self) -> None:
        while not self._closed.is_set():
            try:
                connection, _ = self.listener.accept()
            except OSError:
                return
            threading.Thread(target=self._drip, args=(connection,), daemon=True).start()

    def _drip(self, connection: socket.socket) -> None:
        with contextlib.ExitStack() as stack:
            stack.enter_context(connection)
            if self.tls is not None and self.handshake:
                answer = _server_hello(self.tls, connection)
            else:
                if self.tls is not None:
                    try:
                        connection = self.tls.wrap_socket(connection, server_side=True)
                    except OSError:
                        return
                    stack.enter_context(connection)
                answer = ANSWER if _read_request(connection) else b""
            if not answer:
                return
            with self._lock:
                self.received += 1
            for sent in range(len(answer)):
                if self._closed.is_set():
                    return
                if not self._send(connection, answer[sent : sent + 1]):
                    with self._lock:
                        self.given_up.append(sent)
                    return
            with self._lock:
                self.answered += 1

    def _send(self, connection: socket.socket, byte: bytes) -> bool:
        """Sends one byte when it is due; False when the client went away before."""
        try:
            # Readable before the next byte is due: the client closed its end.
            readable, _, _ = select.select([connection], [], [], self.every)
            if readable and not connection.recv(1):
                return False
            connection.sendall(byte)
        except OSError:
            return False
        return True

    def close(self) -> None:
        self._closed.set()
        self.listener.close()


def _server_hello(tls: ssl.SSLContext, connection: socket.socket) -> bytes:
    """The server's first flight of a TLS handshake (hello, certificate, …) answering the
    client's hello, as bytes to send by hand."""
    incoming, outgoing = ssl.MemoryBIO(), ssl.MemoryBIO()
    server = tls.wrap_bio(incoming, outgoing, server_side=True)
    hello = connection.recv(65536)
    if not hello:
        return b""
    incoming.write(hello)
    with contextlib.suppress(ssl.SSLWantReadError):
        server.do_handshake()
    return outgoing.read()


def _read_request(connection: socket.socket) -> bool:
    """Reads a request's head and its Content-Length body; False when the client left."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = connection.recv(65536)
        if not chunk:
            return False
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    length = 0
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value.strip())
    while len(body) < length:
        chunk = connection.recv(65536)
        if not chunk:
            return False
        body += chunk
    return True
