"""`robotconf status`: the fleet once (exit 0 when in sync), or live until interrupted (--watch)."""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path
from typing import Any

import click
from rich.live import Live
from rich.text import Text

from robotconf.configurator.gcpause import collector_paused
from robotconf.configurator.types import is_robot_id
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.lifecycle import on_stop_signals
from robotconf.contract.wire import Topics
from robotconf.readmodel.retained import RetainedView
from robotconf.readmodel.verdicts import FleetStatus
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.fleet_view import fleet_status_view
from robotconf.workstation.cli.options import repo_option, rev_option
from robotconf.workstation.cli.terminal import is_terminal, plain_text, show, terminal_console
from robotconf.workstation.desk.broker import wait_for_broker
from robotconf.workstation.fleet_reader import FleetReader, open_reader, watch
from robotconf.workstation.fleet_status import (
    DesiredCache,
    confirm_loss,
    fleet_status,
    unknown_when_lost,
)


def _verdict(fleet: FleetStatus) -> ExitCode:
    return ExitCode.OK if fleet.in_sync else ExitCode.FINDINGS


@click.command("status")
@repo_option
@rev_option
@desk_broker_options
@click.option("--watch", "follow", is_flag=True, help="keep showing until interrupted")
@click.option("--json", "as_json", is_flag=True, help="machine-readable output")
@click.option(
    "--wait",
    type=float,
    default=5.0,
    help="give up when the broker's retained messages have not arrived after S seconds",
)
@click.option(
    "--selector",
    "-l",
    "selectors",
    multiple=True,
    metavar="KEY=VALUE",
    help="only robots with this fleet.yaml label (repeat: all of them); the exit code too",
)
def status(
    repo: Path,
    rev: str | None,
    mqtt: BrokerOptions,
    follow: bool,
    as_json: bool,
    wait: float,
    selectors: tuple[str, ...],
) -> ExitCode:
    """Show the fleet: desired vs reported, worst first (exit 0 when every robot is in sync),
    and each robot's drift: what its request needs that the interfaces it reports lack."""
    selector = parse_selector(selectors)
    connection = mqtt.connection()
    topics = Topics(mqtt.prefix)
    desired = DesiredCache(repo, rev)
    changed = threading.Event()

    view, reader = open_reader(connection, mqtt.prefix, desired, changed.set)
    view.start()
    try:
        wait_for_broker(view, wait)
        if not follow:
            messages = view.snapshot()
            fleet = fleet_status(messages, topics, desired)
            lost = confirm_loss(view, fleet, messages, topics)
            if lost is not None:
                fleet = unknown_when_lost(fleet, messages, topics, lost)
            fleet = fleet.select(selector)
            if as_json:
                with collector_paused():  # 10,000 rows' dicts, all alive until printed
                    print(fleet_json(fleet.as_json()))
            else:
                show(fleet_status_view(fleet))
            return _verdict(fleet)
        return _follow(view, reader, changed, as_json, selector)
    finally:
        view.stop()


def fleet_json(found: dict[str, Any]) -> str:
    """`--json`'s text: indented, each robot on one line. Each line is the C encoder's (an
    indented dump goes through json's Python encoder, several times slower at 10,000 rows)."""
    text = json.dumps({**found, "robots": []}, indent=2)
    rows = ",\n".join("    " + json.dumps(row) for row in found["robots"])
    if not rows:
        return text
    # Exactly two blanks: the top level's key (a nested "robots" is indented further).
    return text.replace('\n  "robots": []', '\n  "robots": [\n' + rows + "\n  ]", 1)


def parse_selector(selectors: tuple[str, ...]) -> dict[str, str]:
    """`KEY=VALUE` options as a label selector; a malformed one is a CliError."""
    found: dict[str, str] = {}
    for text in selectors:
        key, equals, value = text.partition("=")
        if not equals or not is_robot_id(key) or not is_robot_id(value):
            raise CliError(
                f"--selector {text!r} is not KEY=VALUE with a label key and value written like "
                "robot ids (e.g. --selector ring=canary)"
            )
        found[key] = value
    return found


def _follow(
    view: RetainedView,
    reader: FleetReader,
    changed: threading.Event,
    as_json: bool,
    selector: dict[str, str],
) -> ExitCode:
    """Per change: one JSON line, or one plain report ended by `---`; on a terminal, a screen."""
    stop = threading.Event()
    on_stop_signals(stop, changed.set)
    code = ExitCode.FINDINGS
    offline = f"(waiting for the broker at {view.connection.address.url}: {{}})"
    if as_json or not is_terminal():
        for found in watch(view, reader, changed, stop):
            fleet = found.select(selector) if found is not None else None
            if fleet is None:
                if not as_json:
                    print(offline.format(view.last_error), flush=True)
                continue
            code = _verdict(fleet)
            if as_json:
                print(json.dumps(fleet.as_json()), flush=True)
            else:
                sys.stdout.write(plain_text(fleet_status_view(fleet)) + "---\n")
                sys.stdout.flush()
        return code

    with Live(console=terminal_console(), auto_refresh=False, transient=False) as live:
        for found in watch(view, reader, changed, stop):
            fleet = found.select(selector) if found is not None else None
            if fleet is None:
                live.update(Text(offline.format(view.last_error)), refresh=True)
                continue
            code = _verdict(fleet)
            live.update(fleet_status_view(fleet), refresh=True)
    return code
