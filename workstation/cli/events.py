"""`robotconf events`: the fleet's timeline, newest first, from the reconciler's ledger (commits
applied and refused, waves, rollbacks, pauses, restarts from the desk and by whom, robots going
offline, drift, deferrals; read-only, never the broker)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from robotconf.contract.errors import CliError, ExitCode
from robotconf.readmodel.ledger import Ledger, LedgerError, find_ledger
from robotconf.readmodel.timeline import DEFAULT_LIMIT, MAX_LIMIT, QueryRefused, event_query
from robotconf.workstation.cli.broker_options import prefix_option
from robotconf.workstation.cli.options import ledger_dir_option, repo_option


@click.command("events")
@repo_option
@prefix_option
@ledger_dir_option
@click.option("--robot", default=None, metavar="ID", help="only this robot's events")
@click.option(
    "--kind",
    default=None,
    metavar="KIND",
    help="only events of this kind (commit_refused, commit_applied, rollout_rolled_back, "
    "robot_restarted, robot_offline, ...; a wrong one lists them all)",
)
@click.option(
    "--since",
    default=None,
    metavar="DURATION",
    help="only events of this last while (e.g. 30m, 2h, 7d)",
)
@click.option(
    "--limit",
    type=int,
    default=DEFAULT_LIMIT,
    show_default=True,
    metavar="N",
    help=f"at most N events, the newest (1 to {MAX_LIMIT})",
)
@click.option("--json", "as_json", is_flag=True, help="machine-readable output (a list)")
def events(
    repo: Path,
    prefix: str,
    state_dir: Path | None,
    robot: str | None,
    kind: str | None,
    since: str | None,
    limit: int,
    as_json: bool,
) -> ExitCode:
    """The fleet's events, newest first, one a line (time, kind, robot, message), from the
    timeline the reconciler keeps in its ledger; exits 1 when none matches."""
    try:
        query = event_query(robot, kind, since, now=time.time(), limit=limit)
    except QueryRefused as exc:
        raise CliError(str(exc)) from None
    path = find_ledger(repo, prefix, state_dir)
    try:
        with Ledger.open(path, read_only=True, check=False) as ledger:
            found = ledger.events(query)
    except LedgerError as exc:
        raise CliError(str(exc)) from None
    if as_json:
        click.echo(json.dumps([event.as_json() for event in found], indent=2))
    elif found:
        click.echo("\n".join(event.line() for event in found))
    else:
        click.echo(f"no events match in {path}")
    return ExitCode.OK if found else ExitCode.FINDINGS
