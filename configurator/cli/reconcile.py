"""`robotconf reconcile`: the fleet follows a git branch until the process is signalled."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import click

from configurator.cli.broker_options import BrokerOptions, broker_options
from configurator.cli.errors import CliError, ExitCode
from configurator.cli.options import repo_option
from configurator.signing import SigningKeyError
from reconciler.lifecycle import log_to_stderr, on_stop_signals
from reconciler.signer import make_signer
from reconciler.source import BranchSource, LocalBranch, RemoteBranch

if TYPE_CHECKING:
    from configurator.mqtt import Connection
    from reconciler.telemetry import Telemetry


def make_source(repo: Path, branch: str, remote: str | None, cache_dir: str | None) -> BranchSource:
    if remote:
        return RemoteBranch(remote, branch, Path(cache_dir) if cache_dir else None)
    source = LocalBranch(repo, branch)
    source.head()  # a branch that does not exist is a typo: say so now
    return source


def make_telemetry(
    connection: Connection, prefix: str, notify: tuple[str, ...], metrics_at: str | None
) -> Telemetry | None:
    """Alerts and metrics, when asked for (the default path starts nothing); a bad URL or
    address, or a port that cannot be listened on, is a one-line error."""
    if not notify and metrics_at is None:
        return None
    from reconciler.notify import Notifier, parse_receiver
    from reconciler.telemetry import Telemetry

    try:
        receivers = [parse_receiver(url, index) for index, url in enumerate(notify, 1)]
    except ValueError as exc:
        raise CliError(str(exc)) from None
    metrics = None
    if metrics_at is not None:
        from reconciler.metrics import Metrics, parse_address

        try:
            host, port = parse_address(metrics_at)
        except ValueError as exc:
            raise CliError(str(exc)) from None
        metrics = Metrics()
        try:
            metrics.serve(host, port)
        except OSError as exc:
            reason = exc.strerror or str(exc)
            raise CliError(f"--metrics {metrics_at}: cannot listen: {reason}") from None
    notifier = None
    if receivers:
        notifier = Notifier(receivers, metrics.notified if metrics is not None else None)
    return Telemetry(connection, prefix, notifier=notifier, metrics=metrics)


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
@click.option(
    "--notify",
    multiple=True,
    metavar="URL",
    help="POST alert events as JSON to this http(s) URL (repeatable); slack:URL posts "
    'a Slack-compatible {"text": ...} instead',
)
@click.option(
    "--metrics",
    "metrics_at",
    default=None,
    metavar="HOST:PORT",
    help="serve Prometheus metrics at http://HOST:PORT/metrics (:PORT: every interface)",
)
def reconcile(
    repo: Path,
    mqtt: BrokerOptions,
    branch: str,
    remote: str | None,
    interval: float,
    signing_key: Path | None,
    cache_dir: str | None,
    notify: tuple[str, ...],
    metrics_at: str | None,
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
    telemetry = make_telemetry(connection, mqtt.prefix, notify, metrics_at)
    log_to_stderr("reconciler")
    controller = Controller(
        source,
        connection,
        mqtt.prefix,
        interval,
        signer=signer,
        on_step=telemetry.on_step if telemetry is not None else None,
    )
    on_stop_signals(callback=controller.stop)
    logging.getLogger("robotconf.reconciler").info(
        "reconciling %s (branch %s) to %s, prefix %s",
        source.description,
        branch,
        connection.address.url,
        mqtt.prefix,
    )
    if telemetry is not None:
        telemetry.start()
    try:
        controller.run()
    finally:
        if telemetry is not None:
            telemetry.stop()
    return ExitCode.OK
