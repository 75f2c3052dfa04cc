"""Alert receivers: each URL gets events POSTed by a worker thread of its own.

A bounded queue (the oldest event dropped, and counted, when full), a deadline per POST and a
few retries with backoff: a receiver that fails or hangs never delays reconciling, nor the others.
"""

from __future__ import annotations

import base64
import collections
import contextlib
import http.client
import json
import logging
import socket
import ssl
import threading
import urllib.error
import urllib.request
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import unquote, urlsplit, urlunsplit

from robotconf.contract.backoff import Backoff
from robotconf.readmodel.events import Event

log = logging.getLogger("robotconf.reconciler")

SLACK = "slack:"
QUEUE = 100  # events waiting per receiver; beyond, the oldest is dropped
TIMEOUT = 5.0  # seconds one POST may take in all: connecting, sending, the answer's status
ATTEMPTS = 3  # POSTs of one event before it is given up
RETRY_INITIAL, RETRY_MAX = 1.0, 10.0
# Outcomes a receiver's metrics count: sent, failed (given up after retries), dropped (queue).
OUTCOMES = ("sent", "failed", "dropped")

Counter = Callable[[str, str], None]  # (receiver name, outcome)
Outcome = tuple[str | None, bool]  # (why the POST failed, or None; whether retrying is pointless)


@dataclass(frozen=True)
class Receiver:
    """A validated receiver URL. `name` is what logs and metrics show: its position and host,
    never its credentials nor its path (a Slack webhook's path is its secret). `url` has no
    credentials: they travel as `authorization` (HTTP Basic, as curl sends them)."""

    url: str = field(repr=False)
    slack: bool
    name: str
    authorization: str | None = field(default=None, repr=False)

    def body(self, event: Event) -> bytes:
        if self.slack:
            return json.dumps({"text": event.text()}).encode()
        return json.dumps(event.as_json()).encode()


NOTIFY_ENV = "ROBOTCONF_NOTIFY"  # receiver URLs, whitespace-separated: the same as --notify
MAX_NOTIFY_FILE_BYTES = 64 * 1024  # --notify-file: some hundreds of URLs, far more than a lab has


@dataclass(frozen=True)
class GivenUrl:
    """A receiver URL as given, and where (for errors that name the place, never the URL)."""

    text: str = field(repr=False)
    where: str


def notify_file_urls(text: str, path: str) -> list[GivenUrl]:
    """The URLs of a --notify-file's text: one per line; blank lines and lines starting with
    `#` are skipped, spaces around a URL dropped. Each is named `PATH:LINE`."""
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        url = line.strip()
        if url and not url.startswith("#"):
            found.append(GivenUrl(url, f"--notify-file {path}:{number}"))
    return found


def given_urls(
    flags: Sequence[str], from_file: Sequence[GivenUrl], environment: str | None
) -> list[GivenUrl]:
    """Every receiver, from --notify, --notify-file and ROBOTCONF_NOTIFY together (a union, as
    the environment and flags combine elsewhere), each URL once, in that order."""
    given = [GivenUrl(url, f"--notify #{n}") for n, url in enumerate(flags, 1)]
    given += from_file
    words = (environment or "").split()
    given += [GivenUrl(url, f"${NOTIFY_ENV} #{n}") for n, url in enumerate(words, 1)]
    seen: set[str] = set()
    once = []
    for url in given:
        if url.text not in seen:
            seen.add(url.text)
            once.append(url)
    return once


def parse_receiver(text: str, index: int = 1, where: str | None = None) -> Receiver:
    """`http(s)://[user:password@]host[:port]/…`, or `slack:https://…` for a Slack-compatible
    `{"text": …}` body. ValueError with a one-line reason, which never repeats any part of
    the URL: a broken one may hold its password where its host or port should be. `where`
    names it in errors (default `--notify #INDEX`)."""
    slack = text.startswith(SLACK)
    url = text[len(SLACK) :] if slack else text
    where = where or f"--notify #{index}"
    # urlsplit drops tabs and line breaks silently, and http.client refuses what is not
    # ASCII or holds a space at the first POST, quoting the URL: both are refused here.
    if not url.isascii() or any(c <= " " or c == "\x7f" for c in url):
        raise ValueError(
            f"{where} must be ASCII without spaces or control characters "
            "(percent-encode them; an international host name in its xn-- form)"
        )
    try:
        parts = urlsplit(url)
        host, port = parts.hostname, parts.port
    except ValueError:
        raise ValueError(
            f"{where} is not a valid URL: scheme://[user:password@]host[:port]/path, with any "
            "@ : / ? # in the user name or password percent-encoded"
        ) from None
    if parts.scheme not in ("http", "https"):
        raise ValueError(f"{where} must be an http:// or https:// URL (optionally prefixed slack:)")
    if not host:
        raise ValueError(f"{where} has no host")
    if "@" in parts.path + parts.query + parts.fragment:
        # `http://user:pa/ss@host/` means host `user`: a password with / ? or # unencoded.
        raise ValueError(
            f"{where} has an @ after its host: percent-encode any / ? # in its password "
            "(%2F %3F %23) and any @ in its path (%40)"
        )
    shown = f"[{host}]" if ":" in host else host
    if port is not None:
        shown += f":{port}"
    authorization = None
    if parts.username is not None:
        pair = f"{unquote(parts.username)}:{unquote(parts.password or '')}"
        authorization = "Basic " + base64.b64encode(pair.encode()).decode("ascii")
    bare = urlunsplit((parts.scheme, parts.netloc.rpartition("@")[2], parts.path, parts.query, ""))
    name = f"#{index} {SLACK if slack else ''}{parts.scheme}://{shown}"
    return Receiver(bare, slack, name, authorization)


class Sender:
    """One receiver's worker thread: POSTs the events queued for it, in order."""

    def __init__(
        self,
        receiver: Receiver,
        count: Counter | None = None,
        *,
        timeout: float = TIMEOUT,
        attempts: int = ATTEMPTS,
        retry: tuple[float, float] = (RETRY_INITIAL, RETRY_MAX),
    ) -> None:
        self.receiver = receiver
        self.timeout = timeout
        self.attempts = attempts
        self.retry = retry
        self._count = count
        self._queue: collections.deque[Event] = collections.deque(maxlen=QUEUE)
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._attempt: _Attempt | None = None  # the POST under way, given up at a stop
        self.dropped = 0
        self._thread = threading.Thread(
            target=self._run, name=f"notify {receiver.name}", daemon=True
        )

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 1.0) -> None:
        """Events still queued are not sent, and a POST under way is given up: a stop does
        not wait for a slow receiver."""
        self._stop.set()
        self._ready.set()
        with self._lock:
            attempt = self._attempt
        if attempt is not None:
            attempt.give_up()
        self._thread.join(timeout)

    def put(self, event: Event) -> None:
        """Never blocks: a full queue drops its oldest event."""
        with self._lock:
            if len(self._queue) == self._queue.maxlen:
                self.dropped += 1
                self._counted("dropped")
                log.warning("notify %s: queue full, oldest event dropped", self.receiver.name)
            self._queue.append(event)
        self._ready.set()

    def _take(self) -> Event | None:
        with self._lock:
            if not self._queue:
                self._ready.clear()
                return None
            return self._queue.popleft()

    def _run(self) -> None:
        while not self._stop.is_set():
            event = self._take()
            if event is None:
                self._ready.wait()
                continue
            try:
                self._deliver(event)
            except Exception:  # a bug here must not end the receiver's thread
                log.exception("notify %s: internal error; event dropped", self.receiver.name)

    def _deliver(self, event: Event) -> None:
        body = self.receiver.body(event)
        backoff = Backoff(*self.retry)
        for attempt in range(1, self.attempts + 1):
            error, final = self._post(body)
            if error is None:
                self._counted("sent")
                return
            if self._stop.is_set():  # given up by the stop, not by the receiver
                return
            if final or attempt == self.attempts:
                log.warning(
                    "notify %s: %s event not delivered after %d attempt(s): %s",
                    self.receiver.name,
                    event.kind.value,
                    attempt,
                    error,
                )
                self._counted("failed")
                return
            if self._stop.wait(backoff.next()):
                return

    def _post(self, body: bytes) -> Outcome:
        headers = {"Content-Type": "application/json", "User-Agent": "robotconf"}
        if self.receiver.authorization is not None:
            headers["Authorization"] = self.receiver.authorization
        request = urllib.request.Request(self.receiver.url, body, headers, method="POST")
        attempt = _Attempt(request, self.timeout, self.receiver.name)
        with self._lock:
            if self._stop.is_set():
                return "stopped", True
            self._attempt = attempt
        try:
            return attempt.result()
        finally:
            with self._lock:
                self._attempt = None

    def _counted(self, outcome: str) -> None:
        if self._count is not None:
            self._count(self.receiver.name, outcome)


class _Attempt:
    """One POST, on a thread of its own, that the sender waits for until its deadline: a
    socket timeout bounds each read, not the POST (a receiver answering a byte at a time
    holds it for ever), and nothing bounds a name lookup. At the deadline the POST is given
    up: its connection is shut down, which ends a read or a TLS handshake at once, and the
    sender goes on (a thread still connecting ends on its own, its socket closed)."""

    def __init__(self, request: urllib.request.Request, timeout: float, name: str) -> None:
        self._request = request
        self.timeout = timeout
        self._lock = threading.Lock()
        self._ended = threading.Event()
        self._outcome: Outcome | None = None
        self._given_up = False
        # A duplicate of each socket the POST connects: shutting it down ends any wait on
        # the connection, even in a TLS handshake (which takes the original's descriptor).
        self._handles: list[socket.socket] = []
        self._thread = threading.Thread(target=self._run, name=f"notify {name} POST", daemon=True)

    def result(self) -> Outcome:
        """Starts the POST and waits for its outcome, at most until its deadline."""
        self._thread.start()
        in_time = self._ended.wait(self.timeout)
        with self._lock:
            if self._outcome is not None:
                return self._outcome
            self._give_up()
        return (f"no answer within {self.timeout:g} s" if not in_time else "given up"), False

    def give_up(self) -> None:
        with self._lock:
            self._give_up()
        self._ended.set()

    def track(self, sock: socket.socket) -> None:
        """Called with each socket the POST connects, before anything is sent on it."""
        with self._lock:
            if self._given_up:
                sock.close()
                raise TimeoutError("the POST was given up")
            self._handles.append(sock.dup())

    def _give_up(self) -> None:  # with the lock held
        self._given_up = True
        self._close_handles(shut=True)

    def _close_handles(self, *, shut: bool) -> None:
        for handle in self._handles:
            if shut:
                with contextlib.suppress(OSError):
                    handle.shutdown(socket.SHUT_RDWR)
            handle.close()
        self._handles.clear()

    def _run(self) -> None:
        try:
            outcome = _post_once(_opener(self), self._request, self.timeout)
        except Exception:  # a bug must end this POST as a failure, not silently
            log.exception("notify: internal error in a POST")
            outcome = "internal error", True
        with self._lock:
            if not self._given_up:
                self._outcome = outcome
            self._close_handles(shut=False)
        self._ended.set()


def _post_once(
    opener: urllib.request.OpenerDirector, request: urllib.request.Request, timeout: float
) -> Outcome:
    """The answer's status is all that counts: its body is not read."""
    try:
        with opener.open(request, timeout=timeout):
            return None, False
    except urllib.error.HTTPError as exc:
        with exc:
            return _refused(exc.code, exc.headers.get("Location"))
    except (OSError, ValueError, http.client.HTTPException) as exc:
        return _why(exc), False


def _refused(code: int, location: str | None) -> Outcome:
    """A 3xx is a mistake in the URL (not retried); a 4xx other than 408 and 429 a refusal."""
    if 300 <= code < 400:
        where = _host_of(location)
        return f"HTTP {code}, a redirect to {where}: not followed (give the URL it names)", True
    return f"HTTP {code}", 400 <= code < 500 and code not in (408, 429)


def _host_of(location: str | None) -> str:
    """Where a redirect points, by its host only: the rest may be a secret."""
    if not location:
        return "nowhere (no Location)"
    try:
        host = urlsplit(location).hostname
    except ValueError:
        return "an unreadable Location"
    return host or "the same host"


def _why(exc: BaseException) -> str:
    """Why a POST failed, told from what cannot quote the receiver's URL (its path is a
    secret): never the text of an exception of urllib or http.client, which may."""
    if isinstance(exc, urllib.error.URLError) and isinstance(exc.reason, BaseException):
        exc = exc.reason
    if isinstance(exc, TimeoutError):
        return "timed out"
    if isinstance(exc, ssl.SSLCertVerificationError):
        return f"TLS: {exc.verify_message}"
    if isinstance(exc, ssl.SSLError):
        return f"TLS: {exc.reason or type(exc).__name__}"
    if isinstance(exc, OSError) and exc.strerror:
        return f"{type(exc).__name__}: {exc.strerror}"
    return type(exc).__name__


class _Tracked(http.client.HTTPConnection):
    """A connection that hands the socket it connects to its attempt (before TLS, so that a
    TLS handshake can be ended too)."""

    attempt: _Attempt | None = None

    def connect(self) -> None:
        super().connect()
        assert self.attempt is not None
        self.attempt.track(self.sock)


class _TrackedTLS(http.client.HTTPSConnection, _Tracked):
    """HTTPS: its `connect` calls _Tracked's (the TCP connection) before the handshake."""


class _HTTPHandler(urllib.request.HTTPHandler):
    def __init__(self, attempt: _Attempt) -> None:
        super().__init__()
        self.attempt = attempt

    def http_open(self, req: urllib.request.Request) -> http.client.HTTPResponse:
        return self.do_open(self._connection, req)

    def _connection(self, host: str, **kwargs: Any) -> http.client.HTTPConnection:
        connection = _Tracked(host, **kwargs)
        connection.attempt = self.attempt
        return connection


class _HTTPSHandler(urllib.request.HTTPSHandler):
    def __init__(self, attempt: _Attempt) -> None:
        super().__init__()
        self.attempt = attempt

    def https_open(self, req: urllib.request.Request) -> http.client.HTTPResponse:
        return self.do_open(self._connection, req)

    def _connection(self, host: str, **kwargs: Any) -> http.client.HTTPConnection:
        connection = _TrackedTLS(host, **kwargs)  # the default context: certificates checked
        connection.attempt = self.attempt
        return connection


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    """A redirect is not followed: urllib would turn the POST into a GET without its body
    (301, 302, 303) and count it sent. It surfaces as the HTTPError of its 3xx instead."""

    def redirect_request(
        self,
        req: urllib.request.Request,
        fp: Any,
        code: int,
        msg: str,
        headers: Any,
        newurl: str,
    ) -> None:
        return None


def _opener(attempt: _Attempt) -> urllib.request.OpenerDirector:
    # The environment's proxy settings apply (urllib's default ProxyHandler): a receiver is
    # reached as curl would reach it.
    return urllib.request.build_opener(_NoRedirect(), _HTTPHandler(attempt), _HTTPSHandler(attempt))


class Notifier:
    """Tells every receiver every event; each on its own thread."""

    def __init__(
        self, receivers: Sequence[Receiver], count: Counter | None = None, timeout: float = TIMEOUT
    ) -> None:
        self.senders = [Sender(receiver, count, timeout=timeout) for receiver in receivers]

    def start(self) -> None:
        for sender in self.senders:
            sender.start()

    def stop(self) -> None:
        for sender in self.senders:
            sender.stop()

    def tell(self, events: Sequence[Event]) -> None:
        for event in events:
            # The message quotes robots: the log's formatter (contract.logsafe) escapes it.
            log.info("event %s: %s", event.kind.value, event.message)
            for sender in self.senders:
                sender.put(event)
