"""`robotconf up`: the whole loop on this machine, shown live on a terminal, as lines otherwise."""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path

import click
from click.core import ParameterSource
from rich.console import Group, RenderableType
from rich.live import Live
from rich.panel import Panel

from robotconf.contract.errors import ExitCode
from robotconf.contract.wire import BROKER_ENV
from robotconf.readmodel.verdicts import FleetStatus
from robotconf.workstation.cli.broker_options import BrokerOptions, broker_options
from robotconf.workstation.cli.fleet_view import fleet_status_view
from robotconf.workstation.cli.options import repo_option
from robotconf.workstation.cli.terminal import is_terminal, safe, terminal_console
from robotconf.workstation.cli.ui import ui_beside, ui_option


class Screen:
    """Lines prefixed `robotconf up:`; on a terminal, the fleet redrawn in place below them.

    A closed terminal (SIGHUP) makes every write fail: from then on nothing is shown, so that
    `up` still stops its agents and brains instead of dying of an I/O error."""

    def __init__(self, live: bool) -> None:
        self.live = live
        self._header: list[str] = []
        self._live: Live | None = None  # while the fleet is shown on a terminal
        self._gone = False  # the terminal or pipe is gone

    def _lost(self) -> None:
        self._gone = True
        self._live = None
        # Python flushes stdout at exit; with nowhere to write, that would print an error.
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, sys.stdout.fileno())
            os.dup2(null, sys.stderr.fileno())
            os.close(null)
        except (OSError, ValueError):
            pass

    def say(self, line: str) -> None:
        if self._gone:
            return
        text = f"robotconf up: {line}"
        try:
            if self._live is not None:
                self._live.console.print(safe(text))  # above the live fleet
            else:
                print(text, flush=True)
        except OSError:
            self._lost()

    def begin(self, header: list[str]) -> None:
        self._header = header
        if self.live and not self._gone:
            self._live = Live(console=terminal_console(), auto_refresh=False)
            try:
                self._live.start()
            except OSError:
                self._lost()

    def show(self, fleet: FleetStatus) -> None:
        if self._live is None:
            return
        from robotconf.workstation.up import refusal_lines

        parts: list[RenderableType] = [safe(line) for line in self._header]
        refused = refusal_lines(fleet.reconciler)
        if refused:  # above the robots, framed in red: nobody misses that a commit was refused
            body = Group(
                *(safe(line, "bold red" if n == 0 else "") for n, line in enumerate(refused))
            )
            parts.append(Panel(body, border_style="bold red", title="commit refused"))
        parts.append(fleet_status_view(fleet))
        try:
            self._live.update(Group(*parts), refresh=True)
        except OSError:
            self._lost()

    def end(self) -> None:
        if self._live is not None:
            try:
                self._live.stop()
            except OSError:
                self._lost()
            self._live = None


@click.command("up")
@repo_option
@broker_options
@click.option("--branch", default=None, help="branch to reconcile (default: the current)")
@click.option("--workdir", default=None, help="where agents keep their files")
@click.option(
    "--port",
    type=click.IntRange(1, 65535),
    default=1883,
    show_default=True,
    help="the embedded broker's port; a free one when it is taken (said, and found by the "
    "desk commands)",
)
@click.option(
    "--no-signing",
    is_flag=True,
    help="do not sign requests (by default up signs them with a key kept in its workdir)",
)
@ui_option
def up(
    repo: Path,
    mqtt: BrokerOptions,
    branch: str | None,
    workdir: str | None,
    port: int,
    no_signing: bool,
    ui_at: str | None,
) -> ExitCode:
    """The whole loop on this machine: broker, reconciler, one agent per robot, live status;
    Ctrl-C stops everything. In another terminal, within the repository, `robotconf status`,
    `robotconf logs ROBOT` and `robotconf restart ROBOT` need no options: they find this up's
    broker, login and signing key in .robotconf/up/desk.json while it runs.

    With --ui, the browser view's operator is whoever holds the token made once into
    .robotconf/up/ui.token (mode 0600; kept for the next up, refused if others may read it):
    up prints a link, http://127.0.0.1:PORT/login?token=..., that logs a browser in to follow
    robots' logs and restart them.

    Each ROS 2 robot reports its interfaces through a stand-in ros2 reading
    .robotconf/up/ROBOT/ros2-graph.json (written at its agent's start with what its request
    needs: edit it and the robot drifts; robotconf draft ROBOT measures it), and
    `touch .robotconf/up/ROBOT/brain.hold` makes it busy (restarts and reloads wait) until
    the file is removed."""
    from robotconf.workstation.up import prepare, run_up, with_operator

    source = click.get_current_context().get_parameter_source("broker")
    origin = f"${BROKER_ENV}" if source is ParameterSource.ENVIRONMENT else "--broker"
    ui = ui_beside(ui_at)
    setup = with_operator(
        dataclasses.replace(prepare(repo, branch, workdir), port=port, broker_origin=origin, ui=ui)
    )
    mqtt.connection()  # the URL, prefix and credentials are checked before anything starts
    screen = Screen(live=is_terminal())
    return run_up(setup, mqtt.broker, mqtt.connection, mqtt.prefix, not no_signing, screen)
