"""`robotconf up`: the whole loop on this machine, shown live on a terminal, as lines otherwise."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Group
from rich.live import Live

from configurator.cli.broker_options import BrokerOptions, broker_options
from configurator.cli.errors import ExitCode
from configurator.cli.fleet_view import fleet_status_view
from configurator.cli.options import repo_option
from configurator.cli.terminal import is_terminal, safe, terminal_console
from reconciler.verdicts import FleetStatus


class Screen:
    """Lines prefixed `robotconf up:`; on a terminal, the fleet redrawn in place below them."""

    def __init__(self, live: bool) -> None:
        self.live = live
        self._header: list[str] = []
        self._live: Live | None = None  # while the fleet is shown on a terminal

    def say(self, line: str) -> None:
        text = f"robotconf up: {line}"
        if self._live is not None:
            self._live.console.print(safe(text))  # above the live fleet
        else:
            print(text, flush=True)

    def begin(self, header: list[str]) -> None:
        self._header = header
        if self.live:
            self._live = Live(console=terminal_console(), auto_refresh=False)
            self._live.start()

    def show(self, fleet: FleetStatus) -> None:
        if self._live is not None:
            head = [safe(line) for line in self._header]
            self._live.update(Group(*head, fleet_status_view(fleet)), refresh=True)

    def end(self) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None


@click.command("up")
@repo_option
@broker_options
@click.option("--branch", default=None, help="branch to reconcile (default: the current)")
@click.option("--workdir", default=None, help="where agents keep their files")
@click.option(
    "--no-signing",
    is_flag=True,
    help="do not sign requests (by default up signs them with a key kept in its workdir)",
)
def up(
    repo: Path, mqtt: BrokerOptions, branch: str | None, workdir: str | None, no_signing: bool
) -> ExitCode:
    """The whole loop on this machine: broker, reconciler, one agent per robot, live status;
    Ctrl-C stops everything."""
    from reconciler.up import prepare, run_up

    setup = prepare(repo, branch, workdir)
    mqtt.connection()  # the URL, prefix and credentials are checked before anything starts
    screen = Screen(live=is_terminal())
    return run_up(setup, mqtt.broker, mqtt.connection, mqtt.prefix, not no_signing, screen)
