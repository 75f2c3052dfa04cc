"""`reconcile --webhook HOST:PORT`: the HTTP edge that turns a git server's push into a fetch now.

Standard-library HTTP on threads of its own, bounded (body size, connections, time per
connection); every request is judged by `reconciler.webhook.judge`, answered, and logged.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import socket
import socketserver
import sys
import threading
import time
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

from configurator.files import NotRegularFile, read_regular
from configurator.textsafe import printable
from reconciler.webhook import MAX_BODY, Answer, Outcome, judge, refused, server_of

log = logging.getLogger("robotconf.reconciler")

MAX_SECRET = 4096
READ_TIMEOUT = 5.0  # seconds a client may stay silent
DEADLINE = 10.0  # seconds a connection may last in all: a slow client cannot hold a thread
MAX_CONNECTIONS = 16  # answered at once; more are closed at once
DRAIN_LIMIT = 16 * 1024 * 1024  # bytes read and dropped after an early answer (413, 411)
_LENGTH = re.compile(r"[0-9]{1,12}")


def read_secret(path: Path) -> bytes:
    """The secret in `path` without surrounding white space; ValueError with a one-line reason
    (which never quotes the file's content)."""
    try:
        data = read_regular(path, MAX_SECRET, follow=True)
    except NotRegularFile as exc:
        raise ValueError(f"--webhook-secret-file {path} {exc}") from None
    except OSError as exc:
        raise ValueError(
            f"cannot read --webhook-secret-file {path}: {exc.strerror or exc}"
        ) from None
    secret = data.strip()
    if not secret:
        raise ValueError(
            f"--webhook-secret-file {path} is empty: write a long random secret into it "
            "(openssl rand -hex 32) and give the git server's webhook the same"
        )
    return secret


class WebhookServer:
    """Listens once `serve`d; a push of `branch` calls `on_push` (it must return at once), and
    every answer's server and outcome are told to `on_answer` (metrics) when given."""

    def __init__(
        self,
        secret: bytes,
        branch: str,
        on_push: Callable[[], None],
        on_answer: Callable[[str, str], None] | None = None,
        *,
        deadline: float = DEADLINE,
        max_connections: int = MAX_CONNECTIONS,
    ) -> None:
        self.secret = secret
        self.branch = branch
        self.deadline = deadline
        self.max_connections = max_connections
        self._on_push = on_push
        self._on_answer = on_answer
        self._http: _HTTPServer | None = None
        self._thread: threading.Thread | None = None
        self._busy_said = 0.0
        self._busy_count = 0

    def serve(self, host: str, port: int) -> None:
        """Listens now (OSError when it cannot) and answers on threads of its own."""
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._http = _HTTPServer((host, port), family, self)
        self._thread = threading.Thread(target=self._serve, name="webhook", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        assert self._http is not None
        return int(self._http.server_address[1])

    def close(self) -> None:
        if self._http is not None:
            self._http.shutdown()
            self._http.server_close()
            self._http = None

    def _serve(self) -> None:
        assert self._http is not None
        try:
            self._http.serve_forever(poll_interval=0.5)
        except Exception as exc:  # the poll still brings every commit, later
            log.error("webhook: stopped answering (%s); commits wait for the next poll", exc)

    # ------------------------------------------------------------------ handler threads

    def judged(self, headers: list[tuple[str, str]], body: bytes, client: str) -> Answer:
        return self.told(judge(headers, body, self.secret, self.branch), client)

    def told(self, answer: Answer, client: str) -> Answer:
        """Logs the answer, counts it, and wakes the reconciler for a push of its branch."""
        if answer.outcome is Outcome.REFUSED:
            log.warning(
                "webhook request from %s refused (%d): %s", client, answer.code, answer.message
            )
        else:
            log.info("%s", answer.message)
        if answer.fetch:
            self._on_push()
        if self._on_answer is not None:
            try:
                self._on_answer(answer.server, answer.outcome.value)
            except Exception as exc:  # metrics must not cost an answer
                log.warning("webhook: counting an answer failed: %s", exc)
        return answer

    def busy(self, client: str) -> None:
        """A connection over the limit is closed unanswered; said at most once a minute."""
        self._busy_count += 1
        now = time.monotonic()
        if now - self._busy_said >= 60.0:
            log.warning(
                "webhook: %d connection(s) closed unanswered, the last from %s: already "
                "answering %d",
                self._busy_count,
                client,
                self.max_connections,
            )
            self._busy_said, self._busy_count = now, 0


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    block_on_close = False

    def __init__(self, address: tuple[str, int], family: int, hook: WebhookServer) -> None:
        self.address_family = family
        self.hook = hook
        self._slots = threading.BoundedSemaphore(hook.max_connections)
        super().__init__(address, _Handler)

    def server_bind(self) -> None:
        # HTTPServer's own would look the host's name up (getfqdn): a slow DNS would hold start.
        socketserver.TCPServer.server_bind(self)
        host, port = self.server_address[:2]
        self.server_name, self.server_port = str(host), int(port)

    def process_request(self, request: Any, client_address: Any) -> None:
        if not self._slots.acquire(blocking=False):
            self.hook.busy(str(client_address[0]))
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._slots.release()

    def handle_error(self, request: Any, client_address: Any) -> None:
        """One line instead of socketserver's traceback on stderr."""
        exc = sys.exc_info()[1]
        log.warning(
            "webhook: the connection from %s failed: %s",
            client_address[0],
            printable(f"{type(exc).__name__}: {exc}")[:300],
        )


class _Handler(BaseHTTPRequestHandler):
    server: _HTTPServer
    timeout = READ_TIMEOUT
    server_version = "robotconf-webhook"
    sys_version = ""

    def setup(self) -> None:
        super().setup()
        self._timer = threading.Timer(self.server.hook.deadline, self._expire)
        self._timer.daemon = True
        self._timer.start()

    def finish(self) -> None:
        self._timer.cancel()
        with contextlib.suppress(OSError):
            super().finish()

    def _expire(self) -> None:
        """Timer thread: the connection has lasted long enough; its reads end now."""
        with contextlib.suppress(OSError):
            self.connection.shutdown(socket.SHUT_RDWR)

    @property
    def _client(self) -> str:
        return str(self.client_address[0])

    def do_POST(self) -> None:
        try:
            self._post()
        except OSError as exc:  # the client went away, or its time was up, mid-answer
            log.warning("webhook: could not answer %s: %s", self._client, exc)
        except Exception as exc:  # a bug answers 500; it never ends the receiver
            log.error(
                "webhook: internal error answering %s: %s",
                self._client,
                printable(f"{type(exc).__name__}: {exc}")[:300],
                exc_info=bool(os.environ.get("ROBOTCONF_DEBUG")),
            )
            with contextlib.suppress(Exception):
                self._reply(500, "internal error")

    def _post(self) -> None:
        headers = list(self.headers.items())
        server = server_of(headers)
        if "Transfer-Encoding" in self.headers or "Content-Length" not in self.headers:
            self._refuse(411, server, "a Content-Length is required (no chunked bodies)")
            self._drain()
            return
        length = self.headers.get_all("Content-Length") or []
        if len(length) != 1 or not _LENGTH.fullmatch(length[0].strip()):
            self._refuse(400, server, "the Content-Length is not one whole number")
            return
        size = int(length[0])
        if size > MAX_BODY:
            self._refuse(413, server, f"the body is {size:,} bytes, over the limit of {MAX_BODY:,}")
            self._drain()
            return
        try:
            body = self.rfile.read(size)
        except OSError:  # silent for READ_TIMEOUT
            body = b""
        if len(body) < size:
            self._refuse(
                408,
                server,
                f"the body did not arrive in full ({size:,} bytes announced): cut, silent for "
                f"{READ_TIMEOUT:g} s, or slower than {self.server.hook.deadline:g} s in all",
            )
            return
        answer = self.server.hook.judged(headers, body, self._client)
        self._reply(answer.code, answer.message)

    def _refuse(self, code: int, server: str, message: str, *, allow: bool = False) -> None:
        """A refusal decided here, before the body is judged: told like the others, answered."""
        self.server.hook.told(refused(code, server, message), self._client)
        self._reply(code, message, allow=allow)

    def _drain(self) -> None:
        """After an answer given before the body was read: what the client still sends is read
        and dropped (a bounded amount, within the deadline), so that closing the connection
        does not reset it before the client has read the answer."""
        left = DRAIN_LIMIT
        with contextlib.suppress(OSError):
            self.wfile.flush()
            self.connection.shutdown(socket.SHUT_WR)
            while left > 0:
                chunk = self.connection.recv(min(left, 65536))
                if not chunk:
                    break
                left -= len(chunk)

    def _not_allowed(self) -> None:
        try:
            command = printable(self.command[:20])
            self._refuse(405, server_of(self.headers.items()), f"{command} is not POST", allow=True)
        except OSError as exc:
            log.warning("webhook: could not answer %s: %s", self._client, exc)

    do_GET = do_HEAD = do_PUT = do_DELETE = do_PATCH = do_OPTIONS = _not_allowed

    def _reply(self, code: int, message: str, *, allow: bool = False) -> None:
        data = (message + "\n").encode("utf-8")
        self.send_response(code)
        self.send_header("Connection", "close")
        if allow:
            self.send_header("Allow", "POST")
        if code != 204:
            self.send_header("Content-Type", "text/plain; charset=utf-8")
            self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        if code != 204 and self.command != "HEAD":
            self.wfile.write(data)
        self.close_connection = True

    def log_request(self, code: int | str = "-", size: int | str = "-") -> None:
        pass  # every request is logged once, by WebhookServer.told

    def log_error(self, format: str, *args: Any) -> None:
        """Requests refused before they reach a handler (bad request line, headers too many
        or too long, silence): one warning line, never their bytes unescaped."""
        log.warning(
            "webhook request from %s refused: %s", self._client, printable(format % args)[:300]
        )
