"""`robotconf restart ROBOT`: start a robot's brain again from the desk, without a commit (the
desk's request_restart, workstation/desk/restart.py); who asks, and the --signing-key option."""

from __future__ import annotations

import getpass
import re
from pathlib import Path

import click

from robotconf.configurator.types import is_robot_id
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.launch import REQUESTER_PATTERN
from robotconf.contract.textsafe import printable
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import F, repo_option
from robotconf.workstation.desk.restart import request_restart
from robotconf.workstation.desk.signing import private_key

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


def signing_key_option(command: F) -> F:
    """--signing-key, as `restart` and `ui` (whose operators restart robots) take it."""
    return click.option(
        "--signing-key",
        type=click.Path(path_type=Path, dir_okay=False),
        default=None,
        help="the Launch Requests' private key: needed when the robots verify signatures "
        "(default: a running robotconf up's, when no broker is given)",
    )(command)


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
