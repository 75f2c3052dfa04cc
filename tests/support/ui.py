"""A real `robotconf ui` process, read over HTTP: its pages, and its server-sent events."""

from __future__ import annotations

import contextlib
import json
import socket
import ssl
import threading
import urllib.error
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from email.message import Message
from pathlib import Path
from typing import Any

from tests.support.fleet import Proc, robotconf_argv
from tests.support.mosquitto import free_port
from tests.support.watch import wait_for


@dataclass
class Answer:
    code: int
    headers: Message
    body: str


class UiProc:
    """`robotconf ui` on a free loopback port; `get` answers never raise for a 4xx or 5xx."""

    def __init__(
        self, repo: Path, broker: str, log: Path, *extra: str, tls: Path | None = None
    ) -> None:
        """`tls`: the CA of its certificate, when it serves HTTPS."""
        self.port = free_port()
        self.scheme = "https" if tls else "http"
        self.context = ssl.create_default_context(cafile=str(tls)) if tls else None
        self.proc = Proc(
            robotconf_argv(
                "ui", "--repo", str(repo), "--broker", broker,
                "--listen", f"127.0.0.1:{self.port}", *extra,
            ),
            log,
        )  # fmt: skip
        wait_for(self._healthy, "robotconf ui answering /healthz")

    def _healthy(self) -> bool | None:
        assert self.proc.alive(), self.proc.output()
        with contextlib.suppress(OSError):
            return self.get("/healthz").code == 200 or None
        return None

    def get(self, path: str, method: str = "GET", headers: dict[str, str] | None = None) -> Answer:
        request = urllib.request.Request(
            f"{self.scheme}://127.0.0.1:{self.port}{path}", method=method, headers=headers or {}
        )
        try:
            with urllib.request.urlopen(request, timeout=30, context=self.context) as answer:
                return Answer(answer.status, answer.headers, answer.read().decode())
        except urllib.error.HTTPError as error:
            return Answer(error.code, error.headers, error.read().decode())

    def wait_page(self, path: str, wanted: Callable[[str], bool], what: str) -> str:
        def probe() -> str | None:
            answer = self.get(path)
            return answer.body if answer.code == 200 and wanted(answer.body) else None

        return wait_for(probe, what)

    def stop(self) -> str:
        self.proc.stop()
        output = self.proc.output()
        assert "Traceback" not in output, output
        return output


class Events:
    """One `/events` stream read on a thread: each event's parsed JSON, in order."""

    def __init__(self, port: int, query: str = "") -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.sock.sendall(f"GET /events{query} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
        self.head = b""
        self.messages: list[dict[str, Any]] = []
        self.ended = False
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        buffer = b""
        self.sock.settimeout(None)
        try:
            while data := self.sock.recv(65536):
                buffer += data
                if not self.head and b"\r\n\r\n" in buffer:
                    self.head, buffer = buffer.split(b"\r\n\r\n", 1)
                while self.head and b"\n\n" in buffer:
                    block, buffer = buffer.split(b"\n\n", 1)
                    self._event(block.decode())
        except OSError:
            pass
        self.ended = True

    def _event(self, block: str) -> None:
        data = [line[6:] for line in block.split("\n") if line.startswith("data: ")]
        if data:
            with self._lock:
                self.messages.append(json.loads("\n".join(data)))

    def seen(self) -> list[dict[str, Any]]:
        with self._lock:
            return list(self.messages)

    def rows(self, robot_id: str) -> list[str]:
        """Every `<tr>` sent for the robot, in order."""
        return [html for m in self.seen() for rid, _, html in m["rows"] if rid == robot_id]

    def wait(self, probe: Callable[[list[dict[str, Any]]], bool], what: str) -> None:
        wait_for(lambda: probe(self.seen()) or None, what)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        self._thread.join(10)


@contextlib.contextmanager
def events(port: int, query: str = "") -> Iterator[Events]:
    stream = Events(port, query)
    try:
        yield stream
    finally:
        stream.close()
