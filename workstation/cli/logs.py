"""`robotconf logs ROBOT`: a brain's log (with its agent's events) from the desk, over MQTT, as
the desk reads it (workstation/desk/logs.py), printed."""

from __future__ import annotations

import sys
import threading
from pathlib import Path

import click

from robotconf.configurator.types import is_robot_id
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.lifecycle import on_stop_signals
from robotconf.contract.wire import MAX_TAIL_LINES, LogsChunk
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import repo_option
from robotconf.workstation.desk.logs import log_chunks, shown
from robotconf.workstation.desk.robot import RobotDesk


def _print(chunk: LogsChunk) -> None:
    if chunk.dropped:
        sys.stderr.write(
            f"robotconf: {chunk.dropped} line(s) left out: the robot sends about 100 lines a "
            "second at most (the whole log is in its work directory)\n"
        )
    if chunk.lines:
        sys.stdout.write("".join(shown(line) + "\n" for line in chunk.lines))
        sys.stdout.flush()


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
