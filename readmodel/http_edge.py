"""The bounded HTTP edge of the reconciler's listeners (`--webhook`, `--metrics`, `--ui`): one
asyncio loop on one thread, so that an open connection costs a file descriptor, never a thread.

Written here because no maintained Python server has these bounds as configuration: uvicorn,
hypercorn and aiohttp cap neither connections per client address nor the time a request head
may take to arrive (their timeouts restart at every byte, so a head trickled a byte a second
holds a connection for ever).
"""

from __future__ import annotations

import asyncio
import contextlib
import http
import http.client
import io
import ipaddress
import logging
import re
import socket
import ssl
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

from robotconf.contract.textsafe import printable
from robotconf.contract.throttle import Throttle

log = logging.getLogger("robotconf.reconciler")

DRAIN_LIMIT = 16 * 1024 * 1024  # bytes read and dropped after an answer, so it is not reset
LINGER = 2.0  # seconds to wait, after an answer, for the client to close its end
START_TIMEOUT = 10.0
_REQUEST_LINE = re.compile(r"([!#$%&'*+.^_`|~0-9A-Za-z-]{1,20}) (\S{1,8000}) HTTP/([0-9])\.([0-9])")
_LENGTH = re.compile(r"[0-9]{1,12}")


@dataclass(frozen=True)
class Limits:
    """What one client, and all of them, may hold of a listener."""

    connections: int = 64  # open at once, in all
    per_client: int = 8  # open at once from one address (IPv6: one /64, what one host gets)
    head: float = 5.0  # seconds from the connection to the end of the request head, however busy
    silence: float = 5.0  # seconds the body may pause
    deadline: float = 10.0  # seconds from the connection to the last byte of the body
    max_head: int = 16 * 1024  # bytes of request line and headers
    max_body: int = 0  # bytes of body, for body_methods
    # The methods whose body is read (and required); other requests are answered unread.
    body_methods: frozenset[str] = field(default_factory=frozenset)
    # A streamed answer (server-sent events): a client that does not take it is cut when this
    # many bytes wait for it, or when a chunk waits longer than `stream_drain` seconds.
    stream_buffer: int = 256 * 1024
    stream_drain: float = 10.0
    stream_idle: float = 15.0  # seconds without a chunk before the stream's keep-alive is sent
    stream_max: float = 3600.0  # seconds a stream lasts at most (an EventSource reconnects)


@dataclass(frozen=True)
class Request:
    client: str  # the address it came from
    method: str
    target: str
    headers: http.client.HTTPMessage
    body: bytes = b""


class Stream(Protocol):
    """A body that arrives over time, until the server ends it or the connection ends."""

    async def next(self) -> bytes | None:
        """The next chunk (awaited as long as it takes); None: the server ends the stream."""
        ...

    def close(self) -> None:
        """The stream is over, whoever ended it: called once, on the edge's loop."""
        ...


class FedStream:
    """A Stream fed from any thread (`put`, `end`); made on the edge's loop (in a service's
    `answer`). At more than `backlog` chunks waiting, the stream ends: a client that far behind
    gets a fresh start when it reconnects, rather than a queue that grows."""

    def __init__(self, backlog: int = 64, on_close: Callable[[], None] | None = None) -> None:
        self._loop = asyncio.get_running_loop()
        self._queue: asyncio.Queue[bytes | None] = asyncio.Queue()
        self._backlog = backlog
        self._on_close = on_close
        self._ended = False
        self.closed = False  # read from any thread: the feeder stops feeding

    def put(self, chunk: bytes) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody reads any more
            self._loop.call_soon_threadsafe(self._put, chunk)

    def end(self) -> None:
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._put, None)

    def _put(self, chunk: bytes | None) -> None:
        if self._ended:
            return  # nothing after the end: the queue stays within its backlog
        if chunk is None or self._queue.qsize() >= self._backlog:
            self._ended = True
            chunk = None
        self._queue.put_nowait(chunk)

    async def next(self) -> bytes | None:
        return await self._queue.get()

    def close(self) -> None:
        self.closed = True
        if self._on_close is not None:
            self._on_close()


@dataclass(frozen=True)
class Response:
    code: int
    body: bytes = b""
    content_type: str = "text/plain; charset=utf-8"
    headers: tuple[tuple[str, str], ...] = ()
    # Streamed after `body`, until it ends: no Content-Length, the connection closes after.
    stream: Stream | None = None
    keepalive: bytes = b""  # sent when the stream is idle for the limits' stream_idle

    @classmethod
    def text(cls, code: int, message: str, *headers: tuple[str, str]) -> Response:
        """One line of text (the log's words), as every refusal is answered."""
        return cls(code, (message + "\n").encode("utf-8"), headers=headers)


class Service(Protocol):
    """What a listener does with requests. Both run on the edge's loop: they must not block."""

    def answer(self, request: Request) -> Response:
        """A whole request: its body read when its method is one of the limits' body_methods."""
        ...

    def refused(self, request: Request, code: int, message: str) -> Response:
        """A request of a body method refused before its body was judged (400, 408, 411, 413):
        for the service to log and count as it does its own refusals."""
        ...


def client_key(host: str) -> str:
    """The part of a client's address that one host owns: the address itself, an IPv6 /64."""
    try:
        address = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return host
    if isinstance(address, ipaddress.IPv6Address):
        if address.ipv4_mapped is not None:
            return str(address.ipv4_mapped)
        return str(ipaddress.IPv6Network((address, 64), strict=False))
    return str(address)


@dataclass(eq=False)
class _Connection:
    key: str
    client: str
    transport: asyncio.Transport
    serial: int
    evicted: bool = False
    answered: bool = False  # the whole answer was handed to the transport

    @property
    def finished(self) -> bool:
        """Answered, and every byte of it with the kernel: the client may already have it all
        (it cannot have it all before), and closing loses none of it."""
        return self.answered and self.transport.get_write_buffer_size() == 0


class _Cut(Exception):
    """The connection ends unanswered; the message says why (for the log)."""


class _Admission:
    """Which connections a listener holds, per address: the caps, counted on open connections
    only (see BoundedHTTPServer). Used on the listener's loop thread alone."""

    def __init__(self, limits: Limits) -> None:
        self.limits = limits
        self.open: dict[str, list[_Connection]] = {}
        self.total = 0

    def admit(self, connection: _Connection) -> str | None:
        """None when `connection` may stay; else why it is closed at once. Decided on what is
        open now: finished connections are not counted (see the class)."""
        mine = self.open.get(connection.key, [])
        busy = {key: [c for c in held if not c.finished] for key, held in self.open.items()}
        holding = len(busy.get(connection.key, []))
        if holding >= self.limits.per_client:
            return f"{holding} already open from {connection.key}, the most one address may hold"
        if len(mine) >= self.limits.per_client:
            self._close_finished(mine)
        if sum(len(held) for held in busy.values()) >= self.limits.connections:
            victim = self._victim(busy, holding)
            if victim is None:
                return f"{self.total} already open, the most it holds"
            victim.evicted = True
            victim.transport.abort()
            self.forget(victim)
        if self.total >= self.limits.connections:
            self._close_finished([c for held in self.open.values() for c in held])
        self.open.setdefault(connection.key, []).append(connection)
        self.total += 1
        return None

    def _close_finished(self, connections: list[_Connection]) -> None:
        """Closes the oldest finished one of `connections` (there is one: the caller counted
        them): closed, not reset, so that its answer still reaches its client."""
        oldest = min((c for c in connections if c.finished), key=lambda c: c.serial)
        self.forget(oldest)
        oldest.transport.close()

    @staticmethod
    def _victim(busy: dict[str, list[_Connection]], holding: int) -> _Connection | None:
        """The oldest open connection of the address holding the most, when making room for a
        client holding `holding` leaves things fairer: that address holds at least two more
        (one more for an address new to the listener)."""
        least = holding + 2 if holding else 1
        candidates = [
            c for connections in busy.values() if len(connections) >= least for c in connections
        ]
        if not candidates:
            return None
        return max(candidates, key=lambda c: (len(busy[c.key]), -c.serial))

    def forget(self, connection: _Connection) -> None:
        mine = self.open.get(connection.key, [])
        if connection in mine:
            mine.remove(connection)
            self.total -= 1
        if not mine:
            self.open.pop(connection.key, None)


class BoundedHTTPServer:
    """HTTP/1.1, one request per connection, every connection bounded by `limits`.

    At the total cap, a client from an address new to the listener, or holding at least two
    fewer connections than the busiest address, still gets in: the busiest address's oldest
    connection is closed for it. So an attack from many addresses cannot keep anyone out.

    The caps count open connections: a finished one (its whole answer with the kernel) only
    lingers to read what its client still sends, and is closed, not counted, when a new
    connection needs its place. A client asking again the moment it has its answer is never
    refused for the connection it just finished, and what is held stays within the caps."""

    def __init__(self, name: str, service: Service, limits: Limits) -> None:
        self.name = name
        self.service = service
        self.limits = limits
        self._held = _Admission(limits)
        self._serial = 0
        self._busy_said = Throttle(60.0)
        self._cut_said = Throttle(60.0, limit=3)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._tls: ssl.SSLContext | None = None

    # ------------------------------------------------------------------ lifecycle (any thread)

    def listen(self, host: str, port: int, tls: ssl.SSLContext | None = None) -> None:
        """Listens now (OSError when it cannot) and answers on a thread of its own; over TLS
        with `tls` (its handshake bounded by the limits' `head`)."""
        self._tls = tls
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.create_server((host, port), family=family, backlog=128)
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT) or self._error is not None:
            self.close()
            raise OSError(f"could not start answering: {self._error or 'no start'}")

    @property
    def port(self) -> int:
        assert self._sock is not None
        return int(self._sock.getsockname()[1])

    @property
    def open_connections(self) -> int:
        return self._held.total

    def close(self) -> None:
        loop, stopping, thread = self._loop, self._stopping, self._thread
        if loop is not None and stopping is not None and thread is not None and thread.is_alive():
            with contextlib.suppress(RuntimeError):  # the loop already ended
                loop.call_soon_threadsafe(stopping.set)
            thread.join(10)
        if self._sock is not None:
            self._sock.close()

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except Exception as exc:  # the poll still brings every commit; metrics pause
            self._error = exc
            log.error("%s: stopped answering (%s)", self.name, exc)
        finally:
            self._ready.set()
            loop.close()

    async def _main(self) -> None:
        self._stopping = asyncio.Event()
        assert self._sock is not None
        tls = {"ssl": self._tls, "ssl_handshake_timeout": self.limits.head} if self._tls else {}
        server = await asyncio.start_server(
            self._serve,
            sock=self._sock,
            limit=self.limits.max_head,
            **tls,  # type: ignore[arg-type]
        )
        self._ready.set()
        await self._stopping.wait()
        server.close()
        for connections in list(self._held.open.values()):
            for connection in connections:
                connection.transport.abort()
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        if tasks:
            await asyncio.wait(tasks, timeout=5)

    def _say(self, throttle: Throttle, line: str) -> None:
        loop = self._loop
        said = throttle.admit(line, loop.time() if loop is not None else 0.0)
        if said is not None:
            log.warning("%s", said)

    # ------------------------------------------------------------------ one connection

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        client = str(peer[0]) if peer else "?"
        self._serial += 1
        transport = writer.transport
        assert isinstance(transport, asyncio.Transport)
        connection = _Connection(client_key(client), client, transport, self._serial)
        refusal = self._held.admit(connection)
        if refusal is not None:
            writer.transport.abort()
            self._say(
                self._busy_said,
                f"{self.name}: a connection from {client} closed unanswered: {refusal}",
            )
            return
        try:
            await self._exchange(connection, reader, writer)
        except _Cut as cut:
            self._say(self._cut_said, f"{self.name}: the connection from {client} {cut}")
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.TimeoutError):
            if connection.evicted:
                self._say(
                    self._cut_said,
                    f"{self.name}: the connection from {client} closed unanswered to make room "
                    f"(its address held the most of {self.limits.connections})",
                )
        except Exception as exc:  # a bug in the edge ends one connection, never the listener
            log.error(
                "%s: internal error with the connection from %s: %s",
                self.name,
                client,
                printable(f"{type(exc).__name__}: {exc}")[:300],
            )
        finally:
            self._held.forget(connection)
            if writer.transport.get_write_buffer_size():  # a client that does not read
                writer.transport.abort()
            else:
                writer.close()

    async def _exchange(
        self, connection: _Connection, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        start = asyncio.get_running_loop().time()
        limits = self.limits
        client = connection.client
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), limits.head)
        except asyncio.TimeoutError:
            raise _Cut(
                f"timed out: no whole request head within {limits.head:g} s; closed unanswered"
            ) from None
        except asyncio.LimitOverrunError:
            response = self._refused_head(client, 431, "the request head is too long")
            await self._send(connection, reader, writer, response, "GET", start)
            return
        request = self._parse(head, client)
        if isinstance(request, Response):
            await self._send(connection, reader, writer, request, "GET", start)
            return
        if request.method in limits.body_methods:
            response = await self._with_body(request, reader, writer, start)
        else:
            response = self._guarded(client, lambda: self.service.answer(request))
        await self._send(connection, reader, writer, response, request.method, start)

    def _parse(self, head: bytes, client: str) -> Request | Response:
        """The request in `head`, or the answer that refuses it (said here: no service saw it)."""
        line, _, rest = head.partition(b"\r\n")
        found = _REQUEST_LINE.fullmatch(line.decode("latin-1"))
        if found is None:
            return self._refused_head(client, 400, "the request line is not METHOD TARGET HTTP/1.x")
        method, target, major, _ = found.groups()
        if major != "1":
            return self._refused_head(client, 505, f"HTTP/{major} is not spoken here: HTTP/1.1")
        try:
            headers = http.client.parse_headers(io.BytesIO(rest))
        except http.client.HTTPException:
            return self._refused_head(client, 431, "too many header lines")
        return Request(client, method, target, headers)

    def _refused_head(self, client: str, code: int, message: str) -> Response:
        self._say(self._cut_said, f"{self.name} request from {client} refused ({code}): {message}")
        return Response.text(code, message)

    async def _with_body(
        self,
        request: Request,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        start: float,
    ) -> Response:
        """The service's answer to a request whose body is read first, or the refusal of its
        framing: a Content-Length is required, within the limit, and arriving in time."""
        headers, limits = request.headers, self.limits

        def refuse(code: int, message: str) -> Response:
            return self._guarded(
                request.client, lambda: self.service.refused(request, code, message)
            )

        if "Transfer-Encoding" in headers or "Content-Length" not in headers:
            return refuse(411, "a Content-Length is required (no chunked bodies)")
        lengths = headers.get_all("Content-Length") or []
        if len(lengths) != 1 or not _LENGTH.fullmatch(lengths[0].strip()):
            return refuse(400, "the Content-Length is not one whole number")
        size = int(lengths[0])
        if size > limits.max_body:
            return refuse(413, f"the body is {size:,} bytes, over the limit of {limits.max_body:,}")
        if size and headers.get("Expect", "").strip().lower() == "100-continue":
            writer.write(b"HTTP/1.1 100 Continue\r\n\r\n")
        body = await self._read_body(reader, size, start)
        if len(body) < size:
            return refuse(
                408,
                f"the body did not arrive in full ({size:,} bytes announced): cut, silent for "
                f"{limits.silence:g} s, or slower than {limits.deadline:g} s in all",
            )
        whole = replace(request, body=body)
        return self._guarded(request.client, lambda: self.service.answer(whole))

    async def _read_body(self, reader: asyncio.StreamReader, size: int, start: float) -> bytes:
        """Up to `size` bytes: fewer when the client pauses longer than `silence`, or the
        deadline since the connection passes."""
        loop = asyncio.get_running_loop()
        chunks: list[bytes] = []
        got = 0
        while got < size:
            left = self.limits.deadline - (loop.time() - start)
            if left <= 0:
                break
            try:
                chunk = await asyncio.wait_for(
                    reader.read(min(65536, size - got)), min(self.limits.silence, left)
                )
            except (asyncio.TimeoutError, ConnectionError):
                break
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        return b"".join(chunks)

    def _guarded(self, client: str, answer: Callable[[], Response]) -> Response:
        """The service's answer; a bug in it answers 500, in one log line."""
        try:
            return answer()
        except Exception as exc:
            log.error(
                "%s: internal error answering %s: %s",
                self.name,
                client,
                printable(f"{type(exc).__name__}: {exc}")[:300],
            )
            return Response.text(500, "internal error")

    async def _send(
        self,
        connection: _Connection,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        response: Response,
        method: str,
        start: float,
    ) -> None:
        """Writes the answer, then reads and drops what the client still sends until it closes
        (a bounded amount and time), so that closing does not reset the answer unread."""
        code = response.code
        try:
            reason = http.HTTPStatus(code).phrase
        except ValueError:
            reason = "Unknown"
        lines = [f"HTTP/1.1 {code} {reason}", "Server: robotconf", "Connection: close"]
        lines += [f"{name}: {value}" for name, value in response.headers]
        body = response.body
        stream = response.stream
        if code == 204:
            body = b""
        elif stream is not None:  # its length is where the connection ends
            lines += [f"Content-Type: {response.content_type}", "Cache-Control: no-store"]
        else:
            lines += [f"Content-Type: {response.content_type}", f"Content-Length: {len(body)}"]
        if method == "HEAD":
            body = b""
        streamed = stream is not None and method != "HEAD" and code != 204
        # Before the bytes go: once the client can have them all, this no longer counts.
        connection.answered = not streamed
        writer.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body)
        loop = asyncio.get_running_loop()
        try:
            await asyncio.wait_for(
                writer.drain(), max(self.limits.deadline - (loop.time() - start), LINGER)
            )
            if streamed:
                assert stream is not None
                await self._stream(reader, writer, response, stream)
                connection.answered = True
        finally:
            if stream is not None:
                stream.close()
        if writer.can_write_eof():
            writer.write_eof()
        until = loop.time() + LINGER
        left = DRAIN_LIMIT
        with contextlib.suppress(asyncio.TimeoutError, ConnectionError):
            while left > 0 and loop.time() < until:
                chunk = await asyncio.wait_for(reader.read(min(left, 65536)), until - loop.time())
                if not chunk:
                    return
                left -= len(chunk)

    async def _stream(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        response: Response,
        stream: Stream,
    ) -> None:
        """Writes the stream's chunks as they come, until it ends, the client leaves, or the
        client is cut: it lets more than `stream_buffer` bytes wait, or does not take a chunk
        within `stream_drain` seconds (a client that reads nothing holds no more than that)."""
        limits = self.limits
        loop = asyncio.get_running_loop()
        until = loop.time() + limits.stream_max
        gone = asyncio.ensure_future(_client_gone(reader))
        chunk: asyncio.Future[bytes | None] | None = None
        try:
            while loop.time() < until:
                if chunk is None:
                    chunk = asyncio.ensure_future(stream.next())
                wait = min(limits.stream_idle, max(until - loop.time(), 0.0))
                either: set[asyncio.Future[object]] = {chunk, gone}  # type: ignore[arg-type]
                await asyncio.wait(either, timeout=wait, return_when=asyncio.FIRST_COMPLETED)
                if gone.done():
                    return  # the client closed its end (or sent more than it may)
                if chunk.done():
                    data, chunk = chunk.result(), None
                    if data is None:
                        return  # the server ends the stream
                else:
                    data = response.keepalive
                if not data:
                    continue
                writer.write(data)
                waiting = writer.transport.get_write_buffer_size()
                if waiting > limits.stream_buffer:
                    raise _Cut(f"does not read its stream ({waiting:,} bytes wait): cut")
                try:
                    await asyncio.wait_for(writer.drain(), limits.stream_drain)
                except asyncio.TimeoutError:
                    raise _Cut(
                        f"did not take a chunk of its stream within {limits.stream_drain:g} s: cut"
                    ) from None
        finally:
            gone.cancel()
            if chunk is not None:
                chunk.cancel()


async def _client_gone(reader: asyncio.StreamReader) -> None:
    """Returns when the client closes its end of a stream, or has sent more than it may (it
    has nothing to send once its request is read)."""
    left = DRAIN_LIMIT
    with contextlib.suppress(ConnectionError):
        while left > 0:
            data = await reader.read(65536)
            if not data:
                return
            left -= len(data)


class EdgeListener:
    """A listener the edge answers for, as its owner (the webhook, the metrics) shows it: served
    with `_listen`, then its port, its open connections, and `close`."""

    _edge: BoundedHTTPServer | None = None

    def _listen(self, name: str, service: Service, limits: Limits, host: str, port: int) -> None:
        """Listens now (OSError when it cannot) and answers on a thread of its own."""
        self._edge = BoundedHTTPServer(name, service, limits)
        self._edge.listen(host, port)

    @property
    def port(self) -> int:
        assert self._edge is not None
        return self._edge.port

    @property
    def open_connections(self) -> int:
        return self._edge.open_connections if self._edge is not None else 0

    def close(self) -> None:
        if self._edge is not None:
            self._edge.close()
            self._edge = None
