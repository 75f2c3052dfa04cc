"""Every listener is bounded: slow and silent clients from a few addresses, on real sockets against
the webhook and metrics servers (in this process, and in a real `robotconf reconcile`), cost no
thread, are cut off, and never keep a genuine request from another address from its answer.

An attacker is told apart from a genuine client by its source address: Linux routes the whole of
127.0.0.0/8 to the loopback, so sockets bound to 127.0.0.2 (and up) come from other "hosts".
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import socket
import threading
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from robotconf.readmodel.http_edge import Limits, client_key
from robotconf.reconciler.metrics import Metrics
from robotconf.reconciler.webhook_server import LIMITS, WebhookServer
from tests.integration.reconciler.test_alerts import scrape, value
from tests.integration.reconciler.test_webhook import SECRET, github, post, push_body
from tests.support.fleet import GitLab, Proc, start_reconciler
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.private import write_private
from tests.support.watch import wait_for

ATTACKER = "127.0.0.2"


def connect_from(source: str, port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.bind((source, 0))
    sock.settimeout(10)
    sock.connect(("127.0.0.1", port))
    sock.settimeout(None)  # blocking: MSG_DONTWAIT then says "nothing yet" at once
    return sock


def closed_by_server(sock: socket.socket) -> bool:
    """True once the server closed (or reset) this connection; never waits."""
    try:
        return sock.recv(1, socket.MSG_DONTWAIT | socket.MSG_PEEK) == b""
    except (BlockingIOError, TimeoutError):
        return False
    except OSError:  # reset
        return True


class Tricklers:
    """Connections that each send one more byte of a request head every second and never end it
    (slowloris), until the server closes them or `stop`."""

    HEAD = b"POST / HTTP/1.1\r\nHost: x\r\nX-GitHub-Event: push\r\nX-Slow: " + b"a" * 10_000

    def __init__(self, sockets: list[socket.socket]) -> None:
        self.sockets = sockets
        self.sent = {id(s): 0 for s in sockets}
        self.cut_while_sending: set[int] = set()  # the server closed them; they still had bytes
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(1.0):
            for sock in self.sockets:
                if id(sock) in self.cut_while_sending:
                    continue
                n = self.sent[id(sock)]
                try:
                    if closed_by_server(sock):
                        raise ConnectionResetError
                    sock.send(self.HEAD[n : n + 1])
                    self.sent[id(sock)] = n + 1
                except OSError:
                    self.cut_while_sending.add(id(sock))

    def still_open(self) -> list[socket.socket]:
        return [s for s in self.sockets if not closed_by_server(s)]

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10)
        for sock in self.sockets:
            sock.close()


@contextlib.contextmanager
def tricklers(source: str, port: int, count: int) -> Iterator[Tricklers]:
    made = Tricklers([connect_from(source, port) for _ in range(count)])
    try:
        yield made
    finally:
        made.stop()


@contextlib.contextmanager
def silent(sources: list[str], port: int, each: int) -> Iterator[list[socket.socket]]:
    """`each` connections from every address of `sources`, in that order, saying nothing."""
    made = [connect_from(source, port) for source in sources for _ in range(each)]
    try:
        yield made
    finally:
        for sock in made:
            sock.close()


def signed_push(port: int) -> tuple[int, str]:
    body = push_body("refs/heads/main", "0" * 40)
    return post(port, body, github(body))


def test_a_slow_header_attack_from_one_address_keeps_no_push_from_another_waiting(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """40 connections trickling a header byte a second from one address: 8 are held (the most
    one address may hold), the others closed at once; a genuine push from another address is
    answered while the 8 are still held. The head deadline is long here, so that "still held"
    cannot depend on the machine's speed; the next test has the real one."""
    pushes: list[int] = []
    limits = dataclasses.replace(LIMITS, head=600.0)
    webhook = WebhookServer(SECRET.encode(), "main", lambda: pushes.append(1), limits=limits)
    caplog.set_level(logging.WARNING, "robotconf.reconciler")
    webhook.serve("127.0.0.1", 0)
    try:
        with tricklers(ATTACKER, webhook.port, 40) as attack:
            wait_for(lambda: len(attack.cut_while_sending) == 32, "32 over the cap closed at once")
            assert len(attack.still_open()) == 8 and webhook.open_connections == 8
            assert signed_push(webhook.port)[0] == 200
            assert pushes == [1]
            # Answered while the attack held its 8: none of them was closed to make room.
            assert len(attack.still_open()) == 8
            wait_for(lambda: webhook.open_connections == 8, "the push's connection closed")
    finally:
        webhook.close()
    busy = [r for r in caplog.messages if "closed unanswered" in r]
    assert len(busy) == 1 and "8 already open from 127.0.0.2" in busy[0]  # once a minute


@pytest.fixture
def reconciler(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path
) -> Iterator[tuple[Proc, int, int]]:
    """A real `robotconf reconcile` with a webhook and metrics, both with the default limits."""
    secret = tmp_path / "webhook.secret"
    write_private(secret, SECRET + "\n")
    port, metrics = free_port(), free_port()
    proc = start_reconciler(
        lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "3600",
        "--webhook", f"127.0.0.1:{port}", "--webhook-secret-file", str(secret),
        "--metrics", f"127.0.0.1:{metrics}",
    )  # fmt: skip
    try:
        wait_for(lambda: "in sync with" in proc.output() or not proc.alive(), "in sync")
        assert proc.alive(), proc.output()
        yield proc, port, metrics
    finally:
        assert proc.stop() == 0, proc.output()[-3000:]
    assert "Traceback" not in proc.output()


def test_a_slowloris_attack_on_a_real_reconciler_is_cut_off_and_pushes_still_fetch(
    reconciler: tuple[Proc, int, int],
) -> None:
    proc, port, metrics = reconciler
    with tricklers(ATTACKER, port, 40) as attack:
        wait_for(lambda: len(attack.cut_while_sending) >= 32, "32 over the cap closed at once")
        assert signed_push(port)[0] == 200
        wait_for(lambda: "push from github for main: fetching" in proc.output(), "the fetch")
        # However busy, none of them ever sends a whole head: the server ends every one of
        # them (its head deadline), while the attacker is still sending.
        wait_for(lambda: len(attack.cut_while_sending) == 40, "every trickler cut off")
        assert attack.still_open() == []
    output = proc.output()
    assert "closed unanswered: 8 already open from 127.0.0.2" in output
    assert "timed out: no whole request head within 5 s" in output
    seen = scrape(metrics)
    assert value(seen, "robotconf_webhooks_total", server="github", outcome="fetch") == 1.0


def threads_of(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/task"))


def test_silent_connections_to_metrics_hold_no_thread_and_a_scrape_is_answered(
    reconciler: tuple[Proc, int, int],
) -> None:
    """120 connections that say nothing, from 15 addresses: the reconciler's thread count does not
    move, at most 64 are held at once, and a scrape from another address is answered."""
    proc, _, metrics = reconciler
    scrape(metrics)  # the listener has answered once: all its threads exist
    before = threads_of(proc.pid)
    sources = [f"127.0.0.{n}" for n in range(10, 25)]
    with silent(sources, metrics, 8) as held:
        wait_for(
            lambda: len([s for s in held if closed_by_server(s)]) >= 120 - 64,
            "the total cap closing what is over it",
        )
        during = threads_of(proc.pid)
        seen = scrape(metrics)
        assert value(seen, "robotconf_ready") == 1.0
        assert len([s for s in held if not closed_by_server(s)]) <= 64
    assert during <= before + 1, (before, during)  # one thread per connection would be 120 more


def test_the_total_cap_holds_and_a_new_address_still_gets_in() -> None:
    """8 addresses, 4 silent connections each, against a cap of 16 in all: 16 are held, none over
    4 from one address, and a scrape from a ninth address is answered: the busiest address's
    oldest connection makes room for it."""
    metrics = Metrics()
    metrics.serve("127.0.0.1", 0, Limits(connections=16, per_client=4, head=600.0))
    try:
        sources = [f"127.0.0.{n}" for n in range(30, 38)]
        with silent(sources, metrics.port, 4) as held:
            wait_for(
                lambda: len([s for s in held if closed_by_server(s)]) == 16,
                "16 closed: each one over the cap, or one it made room for",
            )
            assert metrics.open_connections == 16
            open_from: dict[str, int] = {}
            for sock in held:
                if not closed_by_server(sock):
                    source = sock.getsockname()[0]
                    open_from[source] = open_from.get(source, 0) + 1
            assert sum(open_from.values()) == 16 and max(open_from.values()) <= 4

            with urllib.request.urlopen(f"http://127.0.0.1:{metrics.port}/", timeout=30) as answer:
                assert answer.status == 200 and b"robotconf_ready" in answer.read()
            assert len([s for s in held if not closed_by_server(s)]) == 15  # one made room
            wait_for(lambda: metrics.open_connections == 15, "the scrape's connection closed")
    finally:
        metrics.close()


def test_a_client_is_its_address_and_an_ipv6_host_its_64() -> None:
    assert client_key("192.0.2.7") == "192.0.2.7"
    assert client_key("::ffff:192.0.2.7") == "192.0.2.7"
    assert client_key("2001:db8:1:2:aaaa::1") == client_key("2001:db8:1:2:bbbb::9")
    assert client_key("2001:db8:1:2::1") == "2001:db8:1:2::/64"
    assert client_key("2001:db8:1:3::1") != client_key("2001:db8:1:2::1")


GARBAGE = [
    b"\x00\xff\xfe binary\r\n\r\n",
    b"GET / HTTP/1.1\r\nX: " + b"a" * 20_000 + b"\r\n\r\n",  # a head over 16 KiB
    b"GET / HTTP/1.1\r\n" + b"".join(b"X-%d: y\r\n" % n for n in range(200)) + b"\r\n",
    b"GET /\r\n\r\n",  # HTTP/0.9
    b"GET / HTTP/2.0\r\n\r\n",
    b"GET  /  HTTP/1.1\r\n\r\n",
    "GET /é HTTP/1.1\r\nX: é\r\n\r\n".encode(),
    b"GET / HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello and more",  # a body a GET never reads
    b"POST / HTTP/1.1\r\nContent-Length: 99999999999999\r\n\r\n",
    b"POST / HTTP/1.1\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\nab",
    b"POST / HTTP/1.1\r\nContent-Length: -1\r\n\r\n",
    b"POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n5\r\nhello\r\n0\r\n\r\n",
]


@pytest.mark.parametrize("service", ["webhook", "metrics"])
def test_garbage_is_answered_or_cut_and_the_listener_keeps_answering(
    service: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, "robotconf.reconciler")
    server: WebhookServer | Metrics
    if service == "webhook":
        server = WebhookServer(SECRET.encode(), "main", lambda: None)
        server.serve("127.0.0.1", 0)
    else:
        server = Metrics()
        server.serve("127.0.0.1", 0)
    try:
        for garbage in GARBAGE:
            with connect_from(ATTACKER, server.port) as sock:
                sock.settimeout(30)
                sock.sendall(garbage)
                sock.shutdown(socket.SHUT_WR)
                answer = b""
                with contextlib.suppress(ConnectionResetError):
                    while chunk := sock.recv(65536):
                        answer += chunk
            status = answer.split(b"\r\n", 1)[0]
            assert status == b"" or status.startswith(b"HTTP/1.1 "), (garbage[:40], answer)
            assert not status.startswith(b"HTTP/1.1 5") or b" 505 " in status, answer
            if service == "webhook":
                assert signed_push(server.port)[0] == 200
            else:
                with urllib.request.urlopen(f"http://127.0.0.1:{server.port}/", timeout=30) as ok:
                    assert ok.status == 200
    finally:
        server.close()
    assert not [m for m in caplog.messages if "internal error" in m]
