"""`robotconf logs ROBOT`: a brain's log (with its agent's events) from the desk, over MQTT."""

from __future__ import annotations

import queue
import re
import secrets
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import click

from configurator.types import is_robot_id
from contract.errors import CliError, ExitCode
from contract.textsafe import printable
from contract.wire import (
    LOG_FOLLOW_TTL,
    MAX_TAIL_LINES,
    AgentState,
    AgentStatus,
    LogsChunk,
    LogsRequest,
)
from reconciler.lifecycle import on_stop_signals
from workstation.cli.broker_options import BrokerOptions, desk_broker_options
from workstation.cli.desk import online_robot
from workstation.cli.options import repo_option
from workstation.desk import RobotDesk

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


def _print(chunk: LogsChunk) -> None:
    if chunk.dropped:
        sys.stderr.write(
            f"robotconf: {chunk.dropped} line(s) left out: the robot sends about 100 lines a "
            "second at most (the whole log is in its work directory)\n"
        )
    if chunk.lines:
        sys.stdout.write("".join(shown(line) + "\n" for line in chunk.lines))
        sys.stdout.flush()


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


@click.command("logs")
@click.argument("robot_id", metavar="ROBOT")
@repo_option
@desk_broker_options
@click.option(
    "--lines",
    "-n",
    type=click.IntRange(0, MAX_TAIL_LINES),
    default=50,
    show_default=True,
    help=f"how many of the last lines to show (at most {MAX_TAIL_LINES})",
)
@click.option("--follow", "-f", is_flag=True, help="then show new lines until interrupted")
@click.option(
    "--wait",
    type=click.FloatRange(min=0.1),
    default=10.0,
    show_default=True,
    help="give up when the broker or the robot has not answered after S seconds",
)
def logs(
    robot_id: str, repo: Path, mqtt: BrokerOptions, lines: int, follow: bool, wait: float
) -> ExitCode:
    """Show a robot's brain log, with its agent's events (starts, exits, restarts, refusals).

    The request goes through the broker to the robot's agent, which answers on
    <prefix>/robots/ROBOT/logs only while someone asks: with --follow this command asks again
    every 10 s, and the agent stops streaming 30 s after the last ask. Lines are redacted on
    the robot (agent.yaml's env: values and their encodings, the broker password, private
    keys), cut at 64 KiB, and sent at about 100 lines a second, shared fairly between who asks.
    On a running `robotconf up`'s fleet, with no broker given, its broker and login are found
    in .robotconf/up/desk.json (from --repo or the current folder). Needs the broker's
    `operator` user (robotconf
    broker-config) where the broker has an ACL. Exit 0 when the log was shown, 1 when the robot
    is unknown, offline or does not answer, 2 when the broker cannot be reached.
    """
    if not is_robot_id(robot_id):
        raise CliError(f"{robot_id!r} is not a robot id", ExitCode.FINDINGS)
    connection = mqtt.connection()
    stop = threading.Event()
    if follow:
        on_stop_signals(stop)
    with RobotDesk(connection, mqtt.prefix, robot_id, logs=True) as desk:
        for item in log_chunks(desk, lines, follow, wait, stop.is_set):
            if isinstance(item, LogsChunk):
                _print(item)
            else:
                sys.stderr.write(
                    f"robotconf: {robot_id} went offline; its log goes on when it is back\n"
                )
    return ExitCode.OK
