"""`robotconf ui`: the fleet in a browser, live, until the process is signalled."""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import click

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.lifecycle import log_to_stderr, on_stop_signals
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import F, ledger_dir_option, repo_option
from robotconf.workstation.cli.restart import signing_key_option
from robotconf.workstation.ui import DEFAULT_LISTEN

if TYPE_CHECKING:
    from robotconf.workstation.ui.run import UiOptions

_path = click.Path(path_type=Path)


def ui_option(command: F) -> F:
    """`--ui [HOST:PORT]` of `reconcile` and `up`: serve the UI beside them (loopback only:
    `robotconf ui` is the one that takes a token and TLS for other machines)."""
    return click.option(
        "--ui",
        "ui_at",
        is_flag=False,
        flag_value=DEFAULT_LISTEN,
        default=None,
        metavar="HOST:PORT",
        help="also serve the fleet's web page (robotconf ui) at HOST:PORT (alone: "
        f"{DEFAULT_LISTEN}); loopback only, robotconf ui serves other machines",
    )(command)


def ui_beside(ui_at: str | None) -> UiOptions | None:
    """`--ui` of `reconcile` and `up`, checked before anything starts: read-only, loopback."""
    if ui_at is None:
        return None
    from robotconf.contract.lifecycle import parse_address
    from robotconf.workstation.ui.run import ui_options
    from robotconf.workstation.ui.server import is_loopback

    try:
        host, _ = parse_address(ui_at, "--ui", DEFAULT_LISTEN)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if not is_loopback(host):
        raise CliError(
            f"--ui {ui_at}: serves loopback only; for other machines run robotconf ui with "
            "--operator-token-file and TLS"
        )
    options = ui_options(ui_at, option="--ui")
    return options


@click.command("ui")
@repo_option
@desk_broker_options
@click.option(
    "--listen",
    default=DEFAULT_LISTEN,
    show_default=True,
    metavar="HOST:PORT",
    help="where to serve; another address than loopback needs --operator-token-file and TLS",
)
@click.option(
    "--operator-token-file",
    type=_path,
    default=None,
    metavar="F",
    help="a file (readable by you alone) whose one line is the operators' token: with it, "
    "operators log in and restart robots; without (and without --operators-file), the UI "
    "is read-only",
)
@click.option(
    "--operators-file",
    type=_path,
    default=None,
    metavar="F",
    help="named operators, each with their own token: lines `NAME HASH` (the hash "
    "robotconf hash-token prints); the status and the timeline name who restarted",
)
@click.option(
    "--trusted-proxy",
    "trusted_proxies",
    multiple=True,
    metavar="ADDR",
    help="a reverse proxy's address or network (repeatable): requests from it are "
    "throttled and audited by the X-Forwarded-For address it adds",
)
@click.option("--tls-cert", type=_path, default=None, metavar="F", help="serve HTTPS: certificate")
@click.option("--tls-key", type=_path, default=None, metavar="F", help="... and its private key")
@click.option(
    "--behind-tls-proxy",
    is_flag=True,
    help="a reverse proxy in front terminates TLS (for a non-loopback --listen without --tls-cert)",
)
@signing_key_option
@ledger_dir_option
def ui(
    repo: Path,
    mqtt: BrokerOptions,
    listen: str,
    operator_token_file: Path | None,
    operators_file: Path | None,
    trusted_proxies: tuple[str, ...],
    tls_cert: Path | None,
    tls_key: Path | None,
    behind_tls_proxy: bool,
    signing_key: Path | None,
    state_dir: Path | None,
) -> ExitCode:
    """Serve the fleet as a live web page: the reconciler and a refused commit's diagnostics,
    the rollout, every robot worst first, each robot's page; runs until signalled.

    Viewers look; operators act. With --operator-token-file, an operator logs in at /login
    with the file's token (a session cookie follows, not the token) or sends it as
    `Authorization: Bearer TOKEN` from a script; they restart a robot (its page's Restart,
    confirmed, or POST /robots/ROBOT/restart) through the same signed request as robotconf
    restart (signed with --signing-key when given; the status says `ui.cookie` or
    `ui.bearer` asked) and follow its brain's log on its page. Without a token or with a
    wrong one a restart is refused (401/403); wrong tokens from one address are throttled
    (all of loopback counts as one address).

    With --operators-file instead, each operator logs in with their name and their own token
    (a script sends `Authorization: Bearer NAME:TOKEN`), and the status, the timeline and
    the UI's log say `ui.NAME` asked. Behind a reverse proxy, --trusted-proxy ADDR makes the
    throttle and the log use the client address the proxy adds to X-Forwarded-For.

    A revision's page (/revisions/REV) shows what it achieved beside the revision before,
    from the reconciler's outcome ledger (read-only; --state-dir says where it is); the
    timeline (/timeline) lists the fleet's events kept in the same ledger, newest first."""
    from robotconf.workstation.ui.run import ui_options

    options = ui_options(
        listen,
        operator_token_file,
        tls_cert,
        tls_key,
        behind_tls_proxy,
        signing_key=signing_key or mqtt.signing_key,  # up's own, found with its broker
        operators_file=operators_file,
        trusted_proxies=trusted_proxies,
    )
    _serve(repo, mqtt, options, state_dir)
    return ExitCode.OK


def _serve(repo: Path, mqtt: BrokerOptions, options: UiOptions, state_dir: Path | None) -> None:
    """The UI of checked `options` serving the fleet until the process is signalled."""
    from robotconf.readmodel.ledger import find_ledger
    from robotconf.workstation.ui.revisions import LedgerHistory
    from robotconf.workstation.ui.run import RunningUi

    connection = mqtt.connection()
    log_to_stderr("ui")
    stop = threading.Event()
    on_stop_signals(stop)
    ledger = LedgerHistory(find_ledger(repo, mqtt.prefix, state_dir))
    running = RunningUi(connection, mqtt.prefix, repo, options, history=ledger)
    try:
        logging.getLogger("robotconf.ui").info(
            "serving the fleet of %s (prefix %s, repository %s) at %s",
            connection.address.url,
            mqtt.prefix,
            repo,
            running.url,
        )
        click.echo(f"robotconf ui: {running.url}", err=True)
        while not stop.wait(1.0):
            pass
    finally:
        running.close()
