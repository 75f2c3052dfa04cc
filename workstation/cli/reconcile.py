"""`robotconf reconcile`: the fleet follows a git branch until the process is signalled."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.lifecycle import log_to_stderr, on_stop_signals, parse_address
from robotconf.contract.signing import SigningKeyError
from robotconf.contract.textsafe import printable
from robotconf.contract.trust import Trust, read_trusted
from robotconf.reconciler.notify import (
    MAX_NOTIFY_FILE_BYTES,
    NOTIFY_ENV,
    GivenUrl,
    given_urls,
    notify_file_urls,
)
from robotconf.reconciler.signer import make_signer, make_verifier
from robotconf.reconciler.source import BranchSource, LocalBranch, RemoteBranch
from robotconf.workstation.cli.broker_options import BrokerOptions, broker_options
from robotconf.workstation.cli.options import repo_option
from robotconf.workstation.cli.ui import ui_beside, ui_option

if TYPE_CHECKING:
    from robotconf.contract.mqtt import Connection
    from robotconf.readmodel.verdicts import DesiredRobot
    from robotconf.reconciler.controller import Controller
    from robotconf.reconciler.ledger_feed import LedgerFeed, LedgerSettings
    from robotconf.reconciler.metrics import Metrics
    from robotconf.reconciler.telemetry import Telemetry
    from robotconf.reconciler.webhook_server import WebhookServer
    from robotconf.workstation.ui.run import RunningUi, UiOptions


def make_source(repo: Path, branch: str, remote: str | None, cache_dir: str | None) -> BranchSource:
    if remote:
        return RemoteBranch(remote, branch, Path(cache_dir) if cache_dir else None)
    source = LocalBranch(repo, branch)
    source.head()  # a branch that does not exist is a typo: say so now
    return source


def keep_desired(source: BranchSource) -> Callable[[str, Mapping[str, DesiredRobot]], None] | None:
    """Where the served revisions' desired robots are kept for `status` and the browser view:
    beside a local repository's git data (a remote one's clone is no reader's)."""
    from robotconf.workstation import desired_store

    if isinstance(source, LocalBranch):
        return partial(desired_store.write, source.root)
    return None


def notify_urls(notify: tuple[str, ...], notify_file: Path | None) -> list[GivenUrl]:
    """The receivers of --notify, --notify-file (a secret: checked as ssh checks a key, then
    read bounded) and $ROBOTCONF_NOTIFY together: the last two keep URLs (secrets) off the
    command line."""
    from_file: list[GivenUrl] = []
    if notify_file is not None:
        try:
            raw = read_trusted(notify_file, Trust.SECRET, MAX_NOTIFY_FILE_BYTES)
            text = raw.decode("utf-8")
        except OSError as exc:
            raise CliError(f"--notify-file {notify_file}: {exc.strerror or exc}") from None
        except UnicodeDecodeError:
            raise CliError(f"--notify-file {notify_file} is not UTF-8 text") from None
        from_file = notify_file_urls(text, printable(str(notify_file)))
    return given_urls(notify, from_file, os.environ.get(NOTIFY_ENV))


def make_telemetry(
    connection: Connection,
    prefix: str,
    notify: tuple[str, ...],
    metrics_at: str | None,
    notify_file: Path | None = None,
    source: BranchSource | None = None,
) -> Telemetry:
    """Alerts (to the receivers of notify_urls) and metrics when asked for, and the timeline's
    events always (`start_ledger` hands them to the ledger); a bad URL or address, or a port
    that cannot be listened on, is a one-line error."""
    from robotconf.reconciler.notify import Notifier, parse_receiver
    from robotconf.reconciler.telemetry import Telemetry

    given = notify_urls(notify, notify_file)
    try:
        receivers = [
            parse_receiver(url.text, index, url.where) for index, url in enumerate(given, 1)
        ]
    except ValueError as exc:
        raise CliError(str(exc)) from None
    metrics = None
    if metrics_at is not None:
        from robotconf.reconciler.metrics import Metrics

        try:
            host, port = parse_address(metrics_at, "--metrics", "127.0.0.1:9108")
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
        if metrics is not None:
            metrics.receivers([receiver.name for receiver in receivers])
    telemetry = Telemetry(connection, prefix, notifier=notifier, metrics=metrics)
    telemetry.keep_desired = keep_desired(source) if source is not None else None
    return telemetry


def ledger_settings(
    prefix: str,
    *,
    state_dir: Path | None,
    ledger_max_age: str,
    ledger_max_records: int,
    goal_failure_streak: int,
) -> LedgerSettings:
    """Where and how the outcome ledger is kept (`state_options`), checked before anything
    starts."""
    from robotconf.contract.durations import parse_duration
    from robotconf.readmodel.ledger import default_state_dir
    from robotconf.reconciler.ledger_feed import LedgerSettings

    try:
        age = parse_duration(ledger_max_age)
    except ValueError as exc:
        raise CliError(f"--ledger-max-age: {exc}") from None
    if ledger_max_records < 1000:
        raise CliError("--ledger-max-records must be at least 1000")
    if goal_failure_streak < 1:
        raise CliError("--goal-failure-streak must be at least 1")
    folder = state_dir if state_dir is not None else default_state_dir(prefix)
    return LedgerSettings(folder.absolute(), age, ledger_max_records, goal_failure_streak)


def start_ledger(
    connection: Connection, prefix: str, settings: LedgerSettings, telemetry: Telemetry | None
) -> LedgerFeed:
    """The outcome ledger's feed, started: its file opened (an unreadable one set aside and
    a new one started, said in the log), its session connecting; the telemetry's events are
    kept in it (the timeline). CliError when no ledger can be kept in the state folder at all."""
    from robotconf.readmodel.ledger import LedgerError
    from robotconf.reconciler.ledger_feed import LedgerFeed

    notifier = telemetry.notifier if telemetry is not None else None
    feed = LedgerFeed(
        connection,
        prefix,
        settings,
        metrics=telemetry.metrics if telemetry is not None else None,
        tell=notifier.tell if notifier is not None else None,
    )
    try:
        feed.start()
    except LedgerError as exc:
        raise CliError(f"--state-dir: {exc}") from None
    if telemetry is not None:
        telemetry.keep = feed.keep
    return feed


def state_options(command: Callable[..., ExitCode]) -> Callable[..., ExitCode]:
    """The reconciler's state folder and how its outcome ledger is kept."""
    options = [
        click.option(
            "--state-dir",
            type=click.Path(path_type=Path, file_okay=False),
            default=None,
            metavar="DIR",
            help="the reconciler's state: its outcome ledger (ledger.sqlite3) "
            "(default: $XDG_STATE_HOME/robotconf/reconciler/PREFIX, ~/.local/state/...)",
        ),
        click.option(
            "--ledger-max-age",
            default="30d",
            show_default=True,
            metavar="DURATION",
            help="outcomes and timeline events older than this are removed from the ledger "
            "(s, m, h, d, w)",
        ),
        click.option(
            "--ledger-max-records",
            type=int,
            default=5_000_000,
            show_default=True,
            metavar="N",
            help="the ledger keeps at most this many outcomes, the newest (about 400 bytes each)",
        ),
        click.option(
            "--goal-failure-streak",
            type=int,
            default=3,
            show_default=True,
            metavar="N",
            help="a robot's goals are told failing (--notify) after N failed goals "
            "in a row, and told recovered at its next success",
        ),
    ]
    for option in reversed(options):
        command = option(command)
    return command


@dataclass(frozen=True)
class WebhookOptions:
    host: str
    port: int
    secret: bytes


def webhook_options(webhook_at: str | None, secret_file: Path | None) -> WebhookOptions | None:
    """--webhook and its secret, checked before anything starts (None without --webhook)."""
    if webhook_at is None:
        if secret_file is not None:
            raise CliError("--webhook-secret-file is given without --webhook HOST:PORT")
        return None
    try:
        host, port = parse_address(webhook_at, "--webhook", "127.0.0.1:9292")
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if secret_file is None:
        raise CliError(
            "--webhook needs --webhook-secret-file FILE: the secret the git server signs its "
            "pushes with (never on the command line); refusing to accept unsigned pushes"
        )
    from robotconf.reconciler.webhook_server import read_secret

    try:
        return WebhookOptions(host, port, read_secret(secret_file))
    except ValueError as exc:
        raise CliError(str(exc)) from None


def start_webhook(
    webhook: WebhookOptions, branch: str, on_push: Callable[[], None], metrics: Metrics | None
) -> WebhookServer:
    """The push receiver, listening; a port that cannot be listened on is a one-line error."""
    from robotconf.reconciler.webhook_server import WebhookServer

    receiver = WebhookServer(
        webhook.secret, branch, on_push, metrics.webhook if metrics is not None else None
    )
    if metrics is not None:
        metrics.webhook_servers()
    try:
        receiver.serve(webhook.host, webhook.port)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise CliError(
            f"--webhook {webhook.host}:{webhook.port}: cannot listen: {reason}"
        ) from None
    host = f"[{webhook.host}]" if ":" in webhook.host else webhook.host
    logging.getLogger("robotconf.reconciler").info(
        "webhook: listening at http://%s:%d/ for pushes of %s (GitHub, GitLab, Gitea, Forgejo)",
        host,
        receiver.port,
        branch,
    )
    return receiver


def start_ui(
    options: UiOptions | None, connection: Connection, prefix: str, repo: Path, ledger: Path
) -> RunningUi | None:
    """`--ui`: the fleet's web page beside the loop, read with the reconciler's login; its
    revision pages read the reconciler's own outcome ledger (`ledger`)."""
    if options is None:
        return None
    from robotconf.workstation.ui.revisions import LedgerHistory
    from robotconf.workstation.ui.run import RunningUi

    ui = RunningUi(connection, prefix, repo, options, history=LedgerHistory(ledger))
    logging.getLogger("robotconf.reconciler").info("ui: serving the fleet at %s", ui.url)
    return ui


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
    help="POST alert events as JSON to this http(s) URL (repeatable; user:password@ in it is "
    'sent as HTTP Basic authentication); slack:URL posts a Slack-compatible {"text": ...} instead',
)
@click.option(
    "--notify-file",
    type=click.Path(path_type=Path, dir_okay=False),
    default=None,
    metavar="FILE",
    help="receiver URLs as --notify takes them, one a line (# comments), kept out of ps; "
    "$ROBOTCONF_NOTIFY adds more (whitespace-separated); all of them are used",
)
@click.option(
    "--metrics",
    "metrics_at",
    default=None,
    metavar="HOST:PORT",
    help="serve Prometheus metrics at http://HOST:PORT/metrics (:PORT: every interface)",
)
@click.option(
    "--webhook",
    "webhook_at",
    default=None,
    metavar="HOST:PORT",
    help="accept push events of GitHub, GitLab, Gitea and Forgejo at http://HOST:PORT/ "
    "(:PORT: every interface): a push of --branch fetches at once, not at the next interval",
)
@click.option(
    "--webhook-secret-file",
    type=click.Path(path_type=Path),
    default=None,
    metavar="FILE",
    help="the webhook's secret (GitHub, Gitea, Forgejo: HMAC-SHA256 key; GitLab: token); "
    "required with --webhook",
)
@state_options
@ui_option
def reconcile(
    repo: Path,
    mqtt: BrokerOptions,
    branch: str,
    remote: str | None,
    interval: float,
    signing_key: Path | None,
    cache_dir: str | None,
    notify: tuple[str, ...],
    notify_file: Path | None,
    metrics_at: str | None,
    webhook_at: str | None,
    webhook_secret_file: Path | None,
    ui_at: str | None,
    **ledger_options: Any,
) -> ExitCode:
    """Make the fleet match a git branch: publish one Launch Request per robot, resync every
    --interval seconds, and at once when --webhook receives a push; runs until signalled."""
    from robotconf.readmodel.retained import speaks_mqtt5
    from robotconf.reconciler.controller import Controller

    connection = mqtt.connection()
    if interval <= 0:
        raise CliError("--interval must be a positive number of seconds")
    source = make_source(repo, branch, remote, cache_dir)  # a SourceError is one line, exit 2
    signer, verifier = _keys(signing_key)
    webhook = webhook_options(webhook_at, webhook_secret_file)
    ui_at_options = ui_beside(ui_at)  # checked before anything starts
    kept = ledger_settings(mqtt.prefix, **ledger_options)
    telemetry = make_telemetry(connection, mqtt.prefix, notify, metrics_at, notify_file, source)
    log_to_stderr("reconciler")
    # With MQTT 5 the broker does not send back what the reconciler publishes (No Local):
    # 10,000 requests published are not 10,000 more read. Any 3.1.1 broker still serves.
    no_local = speaks_mqtt5(connection)
    controller = Controller(
        source,
        connection,
        mqtt.prefix,
        interval,
        signer=signer,
        on_step=telemetry.on_step,
        no_local=no_local,
        ledger=kept.path,
        verifier=verifier,
    )
    receiver = None
    if webhook is not None:
        metrics = telemetry.metrics if telemetry is not None else None
        receiver = start_webhook(webhook, branch, controller.resync_now, metrics)
    try:  # after the listeners: a port that cannot be had is the one line said
        ledger = start_ledger(connection, mqtt.prefix, kept, telemetry)
    except CliError:
        if receiver is not None:
            receiver.close()
        raise
    ui = start_ui(ui_at_options, connection, mqtt.prefix, repo, kept.path)
    on_stop_signals(callback=controller.stop)
    _say_started(source, connection, mqtt.prefix, no_local)
    _run(controller, telemetry, receiver, ui, ledger)
    return ExitCode.OK


def _keys(signing_key: Path | None) -> tuple[Any, Any]:
    """The signer of the requests and the key operators' actions are checked with (both None
    when the lab does not sign); a key that cannot be read is one line."""
    try:
        return make_signer(signing_key), make_verifier(signing_key)
    except SigningKeyError as exc:
        raise CliError(str(exc)) from None


def _say_started(source: BranchSource, connection: Connection, prefix: str, no_local: bool) -> None:
    logging.getLogger("robotconf.reconciler").info(
        "reconciling %s (branch %s) to %s, prefix %s (MQTT %s)",
        source.description,
        source.branch,
        connection.address.url,
        prefix,
        "5, No Local" if no_local else "3.1.1",
    )


def _run(
    controller: Controller,
    telemetry: Telemetry | None,
    receiver: WebhookServer | None,
    ui: RunningUi | None = None,
    ledger: LedgerFeed | None = None,
) -> None:
    """The control loop with its telemetry, until signalled; then what serves it stops."""
    if telemetry is not None:
        telemetry.start()
    try:
        controller.run()
    finally:
        if receiver is not None:
            receiver.close()
        if ui is not None:
            ui.close()
        if ledger is not None:
            ledger.stop()
        if telemetry is not None:
            telemetry.stop()
