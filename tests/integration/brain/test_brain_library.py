"""robotconf.brain against a real Unix socket the test listens on (as the agent does): its lines
are contract/goals.py's, a hello comes first on each connection, ready is said again after a
reconnection, a bad argument is a clear ValueError, and a report never blocks the brain — no
listener, a listener that never reads, one that goes away and comes back."""

from __future__ import annotations

import io
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import TypeAdapter

from robotconf import brain
from robotconf.brain import MAX_WAITING, BrainError, Link, read_request
from robotconf.contract.goals import MAX_LINE_BYTES, BrainMessage, GoalLine, Hello, Ready
from tests.support.agents import make_request

MESSAGE: TypeAdapter[object] = TypeAdapter(BrainMessage)


class Listener:
    """The agent's side, reduced: accepts connections on a socket and keeps the lines."""

    def __init__(self, path: Path, read_after: float = 0.0) -> None:
        self.path = path
        self.read_after = read_after  # seconds a connection waits before it is read
        self.server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.server.bind(str(path))
        self.server.listen(4)
        self.lines: list[bytes] = []
        self.connections = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        self.server.settimeout(0.1)
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except (TimeoutError, OSError):
                continue
            self.connections += 1
            threading.Thread(target=self._read, args=(conn,), daemon=True).start()

    def _read(self, conn: socket.socket) -> None:
        buffer = b""
        self._stop.wait(self.read_after)
        conn.settimeout(0.1)
        with conn:
            while not self._stop.is_set():
                try:
                    chunk = conn.recv(65536)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not chunk:
                    return
                buffer += chunk
                *whole, buffer = buffer.split(b"\n")
                self.lines.extend(whole)

    def messages(self) -> list[object]:
        return [MESSAGE.validate_json(line) for line in list(self.lines)]

    def wait(self, count: int) -> list[object]:
        deadline = time.monotonic() + 10
        while len(self.lines) < count and time.monotonic() < deadline:
            time.sleep(0.02)
        return self.messages()

    def close(self) -> None:
        self._stop.set()
        self.server.close()
        self._thread.join(5)
        self.path.unlink(missing_ok=True)


@pytest.fixture
def sock_path(tmp_path: Path) -> Path:
    return tmp_path / "brain.sock"


@pytest.fixture
def listener(sock_path: Path) -> Iterator[Listener]:
    found = Listener(sock_path)
    yield found
    found.close()


def test_a_goal_s_lines_follow_a_hello_and_are_the_contract_s(
    listener: Listener, sock_path: Path
) -> None:
    link = Link(str(sock_path), digest="sha256:" + "a" * 64)
    link.send(brain._line(Ready(type="ready")))
    goal = brain.Goal("Delivery", link)
    goal.progress(0.5, eta=3.0, note="halfway\x1b[31m")
    goal.failed("NAV2_TIMEOUT", "no path " * 500)
    goal.succeeded()  # a second end is nothing
    found = listener.wait(5)
    assert isinstance(found[0], Hello) and found[0].digest == "sha256:" + "a" * 64
    assert isinstance(found[1], Ready)
    steps = [(m.state, m.task) for m in found[2:] if isinstance(m, GoalLine)]
    assert steps == [("started", "Delivery"), ("progress", "Delivery"), ("failed", "Delivery")]
    assert all(len(line) + 1 <= MAX_LINE_BYTES for line in listener.lines)
    ended = found[-1]
    assert isinstance(ended, GoalLine) and ended.code == "NAV2_TIMEOUT"
    assert ended.message is not None and ended.message.endswith("…")  # cut, not refused
    assert len(found) == 5
    link.close()


def test_bad_arguments_are_clear_errors_and_nothing_is_sent(
    listener: Listener, sock_path: Path
) -> None:
    link = Link(str(sock_path))
    goal = brain.Goal("Delivery", link)
    with pytest.raises(ValueError, match="code"):
        goal.failed("not a code!", "x")
    with pytest.raises(ValueError, match="fraction"):
        goal.progress(1.5)
    with pytest.raises(ValueError, match="task"):
        brain.Goal("no spaces in a task", link)
    assert goal.ended is None  # the bad end did not end it
    with pytest.raises(ValueError, match="severity 'loud'"):
        brain.event("loud", "x")
    with pytest.raises(ValueError):
        brain.vitals({f"v{i}": i for i in range(17)})  # at most 16
    goal.canceled()
    found = listener.wait(3)
    assert [m.state for m in found if isinstance(m, GoalLine)] == ["started", "canceled"]
    link.close()


def test_without_a_listener_a_report_returns_at_once_and_waits_bounded(sock_path: Path) -> None:
    link = Link(str(sock_path))  # nobody listens there
    started = time.monotonic()
    for i in range(MAX_WAITING * 4):
        link.send(brain._line(GoalLine(type="goal", id=f"g{i}", task="T", state="progress")))
    assert time.monotonic() - started < 5  # a generous bound: it must not wait per line
    assert link.pending() <= MAX_WAITING + 1 and link.dropped >= MAX_WAITING * 3 - 1


def test_a_listener_that_never_reads_never_blocks_the_brain(sock_path: Path) -> None:
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(sock_path))
    server.listen(1)  # accepts by the kernel's backlog, reads nothing
    try:
        link = Link(str(sock_path))
        started = time.monotonic()
        note = "n" * 700
        for i in range(5000):
            line = GoalLine(type="goal", id="g1", task="T", state="progress", note=note)
            link.send(brain._line(line.model_copy(update={"fraction": i / 5000})))
        assert time.monotonic() - started < 10
        assert link.pending() <= MAX_WAITING + 1 and link.dropped > 0
        # Starts and ends outlive progress when the buffer is full.
        link.send(brain._line(GoalLine(type="goal", id="g2", task="T", state="succeeded")))
        for _ in range(MAX_WAITING):
            link.send(brain._line(GoalLine(type="goal", id="g1", task="T", state="progress")))
        assert link.pending() <= MAX_WAITING + 1
        with link._lock:
            assert any(b'"state":"succeeded"' in line for line in link._waiting)
    finally:
        server.close()


def test_the_agent_going_away_and_back_gets_hello_and_ready_again(sock_path: Path) -> None:
    first = Listener(sock_path)
    link = Link(str(sock_path))
    link.send(brain._line(Ready(type="ready")))
    assert [type(m) for m in first.wait(2)] == [Hello, Ready]
    first.close()
    second = Listener(sock_path)
    try:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not second.lines:
            brain.Goal("Patrol", link).succeeded()  # sent, or kept until the agent is back
            time.sleep(0.2)
        found = second.wait(3)
        assert isinstance(found[0], Hello) and isinstance(found[1], Ready)
        assert any(isinstance(m, GoalLine) and m.task == "Patrol" for m in found)
    finally:
        second.close()
        link.close()


def test_outside_an_agent_lines_are_printed_or_dropped() -> None:
    out = io.StringIO()
    link = Link(None, out=out)
    brain.Goal("Delivery", link).succeeded()
    printed = [MESSAGE.validate_json(line) for line in out.getvalue().splitlines()]
    assert [m.state for m in printed if isinstance(m, GoalLine)] == ["started", "succeeded"]
    quiet = io.StringIO()
    brain.Goal("Delivery", Link(None, report="drop", out=quiet)).succeeded()
    assert quiet.getvalue() == ""


def test_the_request_is_typed_and_a_bad_file_is_one_clear_error(tmp_path: Path) -> None:
    request = make_request()
    path = tmp_path / "request.json"
    path.write_bytes(request.payload())
    found = read_request(path)
    assert (found.robot_id, found.digest, found.revision) == (
        request.robot_id,
        request.digest,
        request.revision,
    )
    assert found.goals == tuple(g.task for g in request.scenario.goals)
    some = next(iter(found.mappings.values()))
    assert some.resolved and some.type and some.kind in ("topic", "service", "action_client")
    logic = next(iter(found.logic_settings), None)
    merged = found.settings(logic)
    assert set(found.robot_settings) <= set(merged)
    assert brain.request(path) is brain.request(path)  # read once
    with pytest.raises(BrainError, match="cannot read the launch request"):
        read_request(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text('{"kind": "LaunchRequest"}')
    with pytest.raises(BrainError, match="is not a launch request: robot_id"):
        read_request(tmp_path / "bad.json")


def test_a_brain_that_ends_its_goal_and_exits_at_once_loses_no_line(sock_path: Path) -> None:
    # More than the socket's buffer holds, to an agent slow to read: the last lines still
    # wait in the library as the brain returns, and go before the process ends.
    listener = Listener(sock_path, read_after=0.5)
    code = (
        "from robotconf import brain\n"
        "brain.ready()\n"
        "g = brain.goal('Delivery')\n"
        "for i in range(200): g.progress(i / 200, note='n' * 790)\n"
        "g.failed('E_LAST', 'the very last line')\n"
    )
    env = {**os.environ, "ROBOTCONF_BRAIN_SOCKET": str(sock_path)}
    try:
        subprocess.run([sys.executable, "-c", code], env=env, check=True, timeout=30)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and b"E_LAST" not in b"".join(listener.lines):
            time.sleep(0.05)
        last = listener.messages()[-1]
        assert isinstance(last, GoalLine) and last.code == "E_LAST"
    finally:
        listener.close()
