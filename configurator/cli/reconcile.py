"""`robotconf reconcile`: the fleet follows a git branch until the process is signalled."""

from __future__ import annotations

import logging
from pathlib import Path

import click

from configurator.cli.broker_options import BrokerOptions, broker_options
from configurator.cli.errors import CliError, ExitCode
from configurator.cli.options import repo_option
from configurator.signing import SigningKeyError
from reconciler.lifecycle import log_to_stderr, on_stop_signals
from reconciler.signer import make_signer
from reconciler.source import BranchSource, LocalBranch, RemoteBranch


def make_source(repo: Path, branch: str, remote: str | None, cache_dir: str | None) -> BranchSource:
    if remote:
        return RemoteBranch(remote, branch, Path(cache_dir) if cache_dir else None)
    source = LocalBranch(repo, branch)
    source.head()  # a branch that does not exist is a typo: say so now
    return source


@click.command("reconcile")
@repo_option
@broker_options
@click.option("--branch", required=True, help="the branch whose head commit is applied")
@click.option("--remote", default=None, help="fetch this URL into a cache clone instead")
@click.option("--interval", type=float, default=30.0, help="resync (and fetch) period in seconds")
@click.option(
    "--signing-key",
    type=click.Path(path_type=Path),
    default=None,
    help="Ed25519 private key (robotconf keys generate): sign every Launch Request",
)
@click.option(
    "--cache-dir",
    default=None,
    help="where --remote is cloned (default: ~/.cache/robotconf/remotes)",
)
def reconcile(
    repo: Path,
    mqtt: BrokerOptions,
    branch: str,
    remote: str | None,
    interval: float,
    signing_key: Path | None,
    cache_dir: str | None,
) -> ExitCode:
    """Make the fleet match a git branch: publish one Launch Request per robot, resync every
    --interval seconds; runs until SIGINT or SIGTERM."""
    from reconciler.controller import Controller

    connection = mqtt.connection()
    if interval <= 0:
        raise CliError("--interval must be a positive number of seconds")
    source = make_source(repo, branch, remote, cache_dir)  # a SourceError is one line, exit 2
    try:
        signer = make_signer(signing_key)
    except SigningKeyError as exc:
        raise CliError(str(exc)) from None
    log_to_stderr("reconciler")
    controller = Controller(source, connection, mqtt.prefix, interval, signer=signer)
    on_stop_signals(callback=controller.stop)
    logging.getLogger("robotconf.reconciler").info(
        "reconciling %s (branch %s) to %s, prefix %s",
        source.description,
        branch,
        connection.address.url,
        mqtt.prefix,
    )
    controller.run()
    return ExitCode.OK
