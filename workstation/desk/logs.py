"""A robot's brain log from the desk, over MQTT: asked of its agent, read in order, and made
safe to show; the one reader of the desk's log channel, for `robotconf logs` and the browser
view's operators alike."""

from __future__ import annotations

import queue
import re
import secrets
import time
from collections.abc import Callable, Iterator

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.textsafe import printable
from robotconf.contract.wire import LOG_FOLLOW_TTL, AgentState, AgentStatus, LogsChunk, LogsRequest
from robotconf.workstation.desk.robot import RobotDesk, online_robot

# A follower asks again this often, so that the agent (which stops LOG_FOLLOW_TTL after the
# newest ask) streams on while it runs and stops soon after it is gone.
ASK_EVERY = LOG_FOLLOW_TTL / 3
# Colours (SGR sequences) are dropped; any other control character is shown escaped.
_SGR = re.compile(r"\x1b\[[0-9;]*m")


def shown(line: str) -> str:
    """A log line as the terminal may print it: no escape sequence from the robot acts."""
    return printable(_SGR.sub("", line))


def _ask(desk: RobotDesk, lines: int, follow: bool, wait: float) -> str:
    session = secrets.token_hex(8)
    request = LogsRequest(session=session, lines=lines, follow=follow)
    topic = desk.topics.logs_request(desk.robot_id)
    if not desk.send(topic, request.model_dump_json().encode("utf-8"), wait):
        raise CliError(
            f"the broker did not take the logs request within {wait:g} s "
            f"({desk.view.last_error or 'no acknowledgement'})"
        )
    return session


def _offline(desk: RobotDesk) -> Iterator[AgentStatus]:
    """While following: the robot's statuses that say it went offline."""
    while True:
        try:
            status = desk.statuses.get_nowait()
        except queue.Empty:
            return
        if status.state is AgentState.OFFLINE:
            yield status


def log_chunks(
    desk: RobotDesk, lines: int, follow: bool, wait: float, stop: Callable[[], bool]
) -> Iterator[LogsChunk | AgentStatus]:
    """The robot's log as `robotconf logs` shows it, once the robot is found online: the tail
    of `lines` lines, then with `follow` the stream (asked again while it is read) and the
    statuses that say the robot went offline, until `stop()`. The one reader of the desk's log
    channel, for the command and the UI's operators; CliError when the robot is not there or
    does not answer within `wait` seconds."""
    online_robot(desk, wait, "its agent cannot answer")
    session = _ask(desk, lines, follow, wait)
    tail_done = False
    deadline = time.monotonic() + wait
    next_ask = time.monotonic() + ASK_EVERY
    while not stop():
        now = time.monotonic()
        if follow and now >= next_ask:
            _ask(desk, 0, True, wait)  # keeps the stream alive; no tail again
            next_ask = now + ASK_EVERY
        if not tail_done and now >= deadline:
            raise CliError(
                f"{desk.robot_id} did not answer within {wait:g} s (its agent may predate "
                "`robotconf logs`, or the ACL does not let this user ask: broker-config's "
                "operator user may)",
                ExitCode.FINDINGS,
            )
        if follow:
            yield from _offline(desk)
        try:
            chunk = desk.chunks.get(timeout=0.2)
        except queue.Empty:
            continue
        if chunk.session == session:
            yield chunk
            if chunk.end:
                tail_done = True
                if not follow:
                    return
        elif chunk.session is None and follow and tail_done:
            yield chunk
