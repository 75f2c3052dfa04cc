"""`robotconf restart ROBOT`: start a robot's brain again from the desk, without a commit."""

from __future__ import annotations

import getpass
import queue
import re
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from configurator.types import is_robot_id
from contract.errors import CliError, ExitCode
from contract.launch import REQUESTER_PATTERN, RestartRequest
from contract.mqtt import Connection
from contract.textsafe import printable
from contract.wire import AgentState, AgentStatus
from workstation.cli.broker_options import BrokerOptions, desk_broker_options
from workstation.cli.desk import online_robot
from workstation.cli.options import F, repo_option
from workstation.desk import RobotDesk

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

_REQUESTER = re.compile(REQUESTER_PATTERN)


def requester(given: str | None, username: str | None) -> str:
    """Who asks, as the agent records it: --as, else the broker user, else the login name."""
    name = given if given is not None else username
    if name is None:
        try:
            name = getpass.getuser()
        except (KeyError, OSError):
            name = "desk"
    if _REQUESTER.fullmatch(name) is None:
        raise CliError(
            f"{name!r} cannot name who asks: letters, digits and . _ @ + - (at most 64), "
            "starting with a letter or digit; pass --as NAME",
            ExitCode.TOOL,
        )
    return name


def _confirmed(desk: RobotDesk, issued_at: float, wait: float) -> AgentStatus | None:
    """The robot's first status that records this restart, within `wait` seconds."""
    deadline = time.monotonic() + wait
    while (left := deadline - time.monotonic()) > 0:
        try:
            status = desk.statuses.get(timeout=min(left, 0.5))
        except queue.Empty:
            continue
        if status.restart_requested_at == issued_at:
            return status
    return None


def private_key(path: Path | None) -> Ed25519PrivateKey | None:
    """The key restarts are signed with, if one is given; a key that cannot be read is a
    one-line error."""
    if path is None:
        return None
    from contract.signing import SigningKeyError, load_private_key

    try:
        return load_private_key(path)
    except SigningKeyError as exc:
        raise CliError(str(exc), ExitCode.TOOL) from None


def signing_key_option(command: F) -> F:
    """--signing-key, as `restart` and `ui` (whose operators restart robots) take it."""
    return click.option(
        "--signing-key",
        type=click.Path(path_type=Path, dir_okay=False),
        default=None,
        help="the Launch Requests' private key: needed when the robots verify signatures "
        "(default: a running robotconf up's, when no broker is given)",
    )(command)


def _send_restart(
    desk: RobotDesk, robot_id: str, by: str, key: Ed25519PrivateKey | None, timeout: float
) -> float:
    """Publish the restart request, signed with `key` if any; when it was issued."""
    # Microseconds, as `sign` stamps them: the status that confirms it names the same time.
    issued_at = round(time.time(), 6)
    request = RestartRequest(robot_id=robot_id, requested_by=by, issued_at=issued_at)
    if key is not None:
        from contract.signing import sign

        request = sign(request, key, issued_at)
    if not desk.send(desk.topics.restart(robot_id), request.payload(), timeout):
        raise CliError(
            f"the broker did not take the restart request "
            f"({desk.view.last_error or 'no acknowledgement'})"
        )
    return request.issued_at


def request_restart(
    connection: Connection,
    prefix: str,
    robot_id: str,
    by: str,
    key: Ed25519PrivateKey | None,
    wait: float,
) -> AgentStatus:
    """Asks `robot_id`'s agent to restart its brain (signed with `key` when given) and waits
    up to `wait` seconds for the status that confirms it: the one way `robotconf restart` and
    the UI's operators restart a robot. Blocks; raises CliError saying why it did not happen
    (robot unknown, offline or idle, broker silent, no confirmation)."""
    with RobotDesk(connection, prefix, robot_id, logs=False) as desk:
        robot = online_robot(desk, min(wait, 10.0), "a restart would be lost")
        status = robot.status
        if status is None or status.state is AgentState.IDLE:
            raise CliError(
                f"nothing to restart: {robot_id} has no launch request (it is idle)",
                ExitCode.FINDINGS,
            )
        issued_at = _send_restart(desk, robot_id, by, key, min(wait, 10.0))
        confirmed = _confirmed(desk, issued_at, wait)
    if confirmed is None:
        raise CliError(
            f"{robot_id} did not confirm the restart within {wait:g} s: its agent refused it "
            "(unsigned or wrongly signed where it verifies, clocks more than 5 minutes apart) "
            f"or never got it (the ACL lets only operators and the reconciler ask); "
            f"robotconf logs {robot_id} shows why",
            ExitCode.FINDINGS,
        )
    return confirmed


@click.command("restart")
@click.argument("robot_id", metavar="ROBOT")
@repo_option
@desk_broker_options
@signing_key_option
@click.option("--as", "as_name", default=None, help="who asks (default: --username, else $USER)")
@click.option(
    "--wait",
    type=click.FloatRange(min=0.1),
    default=30.0,
    show_default=True,
    help="give up when the robot has not confirmed the restart after S seconds",
)
def restart(
    robot_id: str,
    repo: Path,
    mqtt: BrokerOptions,
    signing_key: Path | None,
    as_name: str | None,
    wait: float,
) -> ExitCode:
    """Ask a robot's agent to start its brain again, with the request it has: after `failed`
    (its restart count and backoff start over), or to recover a wedged brain (stopped first:
    SIGTERM, then SIGKILL after the stop timeout). No commit is needed.

    The restart goes through the broker on <prefix>/robots/ROBOT/restart, signed with
    --signing-key when given (on a running `robotconf up`'s fleet, with no broker given, its
    broker, login and key are found in .robotconf/up/desk.json; an agent that verifies Launch
    Requests carries out only a signed restart, once, and only within 5 minutes of when it
    was issued). Needs the broker's `operator` (or `reconciler`) user where the broker has an
    ACL. `robotconf status` shows who asked and when. A busy robot (its brain's hold file)
    confirms it `deferred`: it is carried out once the brain releases the file, or after
    agent.yaml's max_defer. Exit 0 when the robot confirmed it, 1 when the robot is unknown,
    offline, has nothing to restart or did not confirm, 2 when the broker cannot be reached.
    """
    if not is_robot_id(robot_id):
        raise CliError(f"{robot_id!r} is not a robot id", ExitCode.FINDINGS)
    by = requester(as_name, mqtt.username)
    key = private_key(signing_key or mqtt.signing_key)  # up's own, found with its broker
    connection = mqtt.connection()
    confirmed = request_restart(connection, mqtt.prefix, robot_id, by, key, wait)
    # The status message is the robot's own text: escaped, it cannot drive the terminal.
    said = printable(confirmed.message)
    print(f"{robot_id}: restart requested by {by}: {confirmed.state.value} ({said})")
    return ExitCode.OK
