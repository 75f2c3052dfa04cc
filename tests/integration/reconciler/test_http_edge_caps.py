"""The bounded edge's caps hold exactly, on real sockets: they count open connections only, so
clients asking back to back within the caps are always answered, and one past a cap is refused.

A connection stops counting once its whole answer is with the kernel: a client that asks again
the moment it has read its answer must not find its last connection (still lingering on the
server, or not yet seen closed) counted against it.
"""

from __future__ import annotations

import socket
import threading

from robotconf.readmodel.http_edge import Limits
from tests.integration.reconciler.test_http_edge_stream import edge, read_to_end
from tests.integration.reconciler.test_listeners import closed_by_server, connect_from
from tests.support.watch import wait_for

ROUNDS = 150  # requests per client, each on a new connection opened as the last one ends


def ask(port: int, source: str, close: bool = True) -> tuple[bytes, socket.socket]:
    """One GET /plain from `source`: the whole answer (b"" when refused), and the socket."""
    sock = connect_from(source, port)
    try:
        sock.sendall(b"GET /plain HTTP/1.1\r\nHost: x\r\n\r\n")
        answer = read_to_end(sock) if close else _read_answer(sock)
    except OSError:  # reset: refused
        answer = b""
    if close:
        sock.close()
    return answer, sock


def _read_answer(sock: socket.socket) -> bytes:
    """Up to the end of a `plain` answer, leaving the connection open from this side."""
    sock.settimeout(20)
    got = b""
    while not got.endswith(b"plain\n"):
        data = sock.recv(65536)
        if not data:
            break
        got += data
    return got


def back_to_back(port: int, sources: list[str]) -> list[bytes]:
    """One thread per source, each asking ROUNDS times in a row; every answer, in no order."""
    answers: list[bytes] = []
    lock = threading.Lock()

    def client(source: str) -> None:
        for _ in range(ROUNDS):
            answer, _ = ask(port, source)
            with lock:
                answers.append(answer)

    threads = [threading.Thread(target=client, args=(s,)) for s in sources]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return answers


def test_clients_at_the_per_address_cap_asking_back_to_back_are_all_answered() -> None:
    with edge(Limits(connections=64, per_client=8)) as (server, _):
        answers = back_to_back(server.port, ["127.0.0.1"] * 8)
        assert len(answers) == 8 * ROUNDS
        refused = [a for a in answers if not a.endswith(b"plain\n")]
        assert refused == []
        wait_for(lambda: server.open_connections == 0 or None, "every connection forgotten")


def test_clients_at_the_total_cap_asking_back_to_back_are_all_answered() -> None:
    with edge(Limits(connections=16, per_client=4)) as (server, _):
        sources = [f"127.0.0.{n}" for n in range(40, 44) for _ in range(4)]
        answers = back_to_back(server.port, sources)
        assert [a for a in answers if not a.endswith(b"plain\n")] == []


def test_answered_connections_left_open_by_their_client_make_room_within_the_cap() -> None:
    """Clients that read their answer but keep their end open (the server lingers to read what
    they still send) do not count: a ninth is answered, and what the server holds stays at the
    cap (the oldest lingering connection is closed for it, its answer already delivered)."""
    with edge(Limits(connections=64, per_client=8)) as (server, _):
        kept = [ask(server.port, "127.0.0.1", close=False) for _ in range(8)]
        assert all(answer.endswith(b"plain\n") for answer, _ in kept)
        answer, _ = ask(server.port, "127.0.0.1")
        assert answer.endswith(b"plain\n")
        assert server.open_connections <= 8
        for _, sock in kept:
            sock.close()


def test_one_past_the_per_address_cap_is_refused_and_another_address_answered() -> None:
    with edge(Limits(connections=64, per_client=8, head=600.0)) as (server, _):
        held = [connect_from("127.0.0.1", server.port) for _ in range(8)]
        wait_for(lambda: server.open_connections == 8 or None, "8 connections open")
        past, _ = ask(server.port, "127.0.0.1")
        assert past == b""  # closed unanswered
        assert not any(closed_by_server(sock) for sock in held)
        other, _ = ask(server.port, "127.0.0.5")
        assert other.endswith(b"plain\n")
        held[0].close()
        wait_for(lambda: server.open_connections == 7 or None, "one of the 8 gone")
        again, _ = ask(server.port, "127.0.0.1")
        assert again.endswith(b"plain\n")  # within the cap again: answered
        for sock in held[1:]:
            sock.close()


def test_one_past_the_total_cap_from_a_held_address_is_refused() -> None:
    """At the total cap with every address holding alike, a newcomer holding as many is
    refused: nothing fairer comes of closing another's connection."""
    with edge(Limits(connections=8, per_client=5, head=600.0)) as (server, _):
        held = [connect_from(f"127.0.0.{n}", server.port) for n in (50, 51) for _ in range(4)]
        wait_for(lambda: server.open_connections == 8 or None, "8 connections open")
        extra = connect_from("127.0.0.50", server.port)  # its address is at its cap too
        wait_for(lambda: closed_by_server(extra) or None, "the ninth refused")
        assert not any(closed_by_server(sock) for sock in held)
        extra.close()
        for sock in held:
            sock.close()
