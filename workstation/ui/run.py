"""Starting the UI, for `robotconf ui`, `reconcile --ui` and `up --ui`: where it listens (and
whether that is allowed), its TLS, the live fleet and the HTTP service, stopped together."""

from __future__ import annotations

import ssl
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from robotconf.contract.errors import CliError
from robotconf.contract.lifecycle import parse_address
from robotconf.contract.mqtt import Connection
from robotconf.readmodel.http_edge import BoundedHTTPServer
from robotconf.workstation.desk.signing import private_key
from robotconf.workstation.ui import DEFAULT_LISTEN
from robotconf.workstation.ui.actions import Actions
from robotconf.workstation.ui.auth import OperatorAuth
from robotconf.workstation.ui.clients import parse_proxies
from robotconf.workstation.ui.commit_reader import CommitReader
from robotconf.workstation.ui.logtail import LogTails
from robotconf.workstation.ui.restarts import Restarts
from robotconf.workstation.ui.revisions import CachedHistory, LedgerHistory, RevisionHistory
from robotconf.workstation.ui.rollout_decisions import Decisions
from robotconf.workstation.ui.server import UiService, is_loopback, serve
from robotconf.workstation.ui.state import LiveFleet

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey


@dataclass(frozen=True)
class UiOptions:
    host: str
    port: int
    auth: OperatorAuth
    tls: ssl.SSLContext | None = None
    key: Ed25519PrivateKey | None = None  # operators' restarts are signed with it
    link_login: bool = False  # /login?token=... logs in (up's printed link; loopback only)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{self.port}/"


def ui_options(
    listen: str,
    token_file: Path | None = None,
    tls_cert: Path | None = None,
    tls_key: Path | None = None,
    behind_tls_proxy: bool = False,
    option: str = "--listen",
    signing_key: Path | None = None,
    operators_file: Path | None = None,
    trusted_proxies: Sequence[str] = (),
) -> UiOptions:
    """The checked options, before anything starts; CliError (exit 2) with what to do. A
    non-loopback address needs operator authentication and TLS (or a proxy that does it)."""
    try:
        host, port = parse_address(listen, option, DEFAULT_LISTEN)
        proxies = parse_proxies(trusted_proxies)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if (tls_cert is None) != (tls_key is None):
        raise CliError("--tls-cert and --tls-key go together: the certificate and its key")
    if tls_cert is not None and behind_tls_proxy:
        raise CliError("--behind-tls-proxy says a proxy does TLS: give it or --tls-cert, not both")
    if not is_loopback(host):
        if token_file is None and operators_file is None:
            raise CliError(
                f"{option} {listen} is reachable from other machines: it needs "
                "--operators-file F (each operator logs in with their own token) or "
                "--operator-token-file F (one token) and TLS "
                "(--tls-cert F --tls-key F, or --behind-tls-proxy); or listen on 127.0.0.1"
            )
        if tls_cert is None and not behind_tls_proxy:
            raise CliError(
                f"{option} {listen} is reachable from other machines: serve it over TLS "
                "(--tls-cert F --tls-key F), or say that a reverse proxy terminates TLS "
                "(--behind-tls-proxy)"
            )
    # Over TLS, here or at a proxy, the browser sends the session cookie over TLS only.
    auth = OperatorAuth.from_file(
        token_file,
        operators_file=operators_file,
        proxies=proxies,
        secure=tls_cert is not None or behind_tls_proxy,
    )
    tls = _tls(tls_cert, tls_key) if tls_cert and tls_key else None
    return UiOptions(host, port, auth, tls, private_key(signing_key))


def _tls(cert: Path, key: Path) -> ssl.SSLContext:
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        context.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError) as exc:
        raise CliError(f"cannot use --tls-cert {cert} --tls-key {key}: {exc}") from None
    return context


class RunningUi:
    """The UI serving one fleet until `close`."""

    def __init__(
        self,
        connection: Connection,
        prefix: str,
        repo: Path,
        options: UiOptions,
        history: RevisionHistory | None = None,
    ) -> None:
        """`history`: the reconciler's outcome ledger, for the revision pages (None: they say
        that none is open here, and show what the robots report now)."""
        self.live = LiveFleet(connection, prefix, repo)
        self.service = UiService(self.live, options.auth)
        if history is not None:
            self.service.history = CachedHistory(history)
            if isinstance(history, LedgerHistory):  # the same file holds the timeline
                self.service.timeline = history
        self.service.commits = CommitReader(repo)
        actions = Actions(
            options.auth,
            Restarts(connection, prefix, options.key),
            LogTails(connection, prefix),
            decisions=Decisions(connection, prefix, options.key),
            link_login=options.link_login,
        )
        self.service.routes += actions.routes()
        self.service.restart_outcome = actions.outcome_html
        self.options = options
        self.live.start()
        try:
            self.edge: BoundedHTTPServer = serve(
                self.service, options.host, options.port, options.tls
            )
        except OSError as exc:
            self.live.stop()
            reason = exc.strerror or str(exc)
            raise CliError(
                f"the UI cannot listen at {options.host}:{options.port}: {reason}"
            ) from None

    @property
    def url(self) -> str:
        host = f"[{self.options.host}]" if ":" in self.options.host else self.options.host
        scheme = "https" if self.options.tls else "http"
        return f"{scheme}://{host}:{self.edge.port}/"

    def close(self) -> None:
        self.live.stop()
        self.edge.close()
