"""Options of the commands that talk to a broker, gathered into one checked Connection."""

from __future__ import annotations

import dataclasses
import functools
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from robotconf.contract.errors import CliError
from robotconf.contract.logsafe import escape_stray_records
from robotconf.contract.mqtt import Connection, check_tls_files
from robotconf.contract.wire import BROKER_ENV, DEFAULT_BROKER, DEFAULT_PREFIX, validate_prefix
from robotconf.workstation.cli.options import F


def prefix_option(command: F) -> F:
    return click.option(
        "--prefix", default=DEFAULT_PREFIX, help=f"topic prefix (default: {DEFAULT_PREFIX})"
    )(command)


@dataclass(frozen=True)
class BrokerOptions:
    """The broker options of one command line, as given."""

    broker: str | None
    prefix: str
    username: str | None
    password_file: Path | None
    ca_file: Path | None
    cert_file: Path | None
    key_file: Path | None
    insecure: bool
    # From a running `robotconf up`'s desk file, when no broker was given: its signing key
    # (for `restart`) and where the broker came from (for messages).
    signing_key: Path | None = None
    origin: str | None = None

    def connection(self, url: str | None = None) -> Connection:
        """The connection to `url` (default: --broker, else the default broker), checked now
        rather than in a network thread; raises CliError."""
        connection = Connection(
            url=url or self.broker or DEFAULT_BROKER,
            username=self.username,
            password_file=self.password_file,
            ca_file=self.ca_file,
            cert_file=self.cert_file,
            key_file=self.key_file,
            insecure=self.insecure,
        )
        try:
            connection.address  # noqa: B018 - parses the URL
            validate_prefix(self.prefix)
        except ValueError as exc:
            raise CliError(str(exc)) from None
        if connection.password_file is not None:
            try:
                connection.password()
            except OSError as exc:
                raise CliError(
                    f"cannot read --password-file {connection.password_file}: {exc.strerror}"
                ) from None
        try:
            if connection.address.tls:
                check_tls_files(connection)
        except OSError as exc:
            raise CliError(f"cannot use {exc.filename or 'a TLS file'}: {exc.strerror}") from None
        return connection


_BROKER_FIELDS = (
    "broker",
    "prefix",
    "username",
    "password_file",
    "ca_file",
    "cert_file",
    "key_file",
    "insecure",
)


def _given(name: str) -> bool:
    """True when option `name` was given on the command line or by its environment variable."""
    source = click.get_current_context().get_parameter_source(name)
    return source not in (None, click.core.ParameterSource.DEFAULT)


def with_up_desk(mqtt: BrokerOptions, start: Path) -> BrokerOptions:
    """`mqtt`, completed from the desk file of a `robotconf up` running in `start` (or above)
    when no broker was given (--broker, $ROBOTCONF_BROKER); options given still win."""
    from robotconf.workstation.up_desk import find_desk

    if _given("broker"):
        return mqtt
    desk, note = find_desk(start)
    if note is not None:
        sys.stderr.write(f"robotconf: note: {note}\n")
    if desk is None:
        return mqtt
    return dataclasses.replace(
        mqtt,
        broker=desk.broker,
        prefix=mqtt.prefix if _given("prefix") else desk.prefix,
        username=mqtt.username or desk.username,
        password_file=mqtt.password_file or desk.password_file,
        ca_file=mqtt.ca_file or desk.ca_file,
        cert_file=mqtt.cert_file or desk.cert_file,
        key_file=mqtt.key_file or desk.key_file,
        insecure=mqtt.insecure or desk.insecure,
        signing_key=desk.signing_key,
        origin=f"robotconf up's broker (pid {desk.pid})",
    )


def broker_options(command: F) -> F:
    """Declares the broker options and hands them to `command` as one `mqtt: BrokerOptions`."""
    return _declare(command, find_up=False)


def desk_broker_options(command: F) -> F:
    """The broker options of a desk command: without a broker given, a running `robotconf up`'s
    broker, found from --repo or the current folder (workstation/up_desk.py)."""
    return _declare(command, find_up=True)


def _declare(command: F, *, find_up: bool) -> F:
    @functools.wraps(command)
    def gathered(*args: Any, **kwargs: Any) -> Any:
        escape_stray_records()  # these commands read what robots publish
        mqtt = BrokerOptions(**{name: kwargs.pop(name) for name in _BROKER_FIELDS})
        if find_up:
            mqtt = with_up_desk(mqtt, kwargs.get("repo") or Path.cwd())
        return command(*args, mqtt=mqtt, **kwargs)

    path = click.Path(path_type=Path)
    options = [
        click.option(
            "--broker",
            envvar=BROKER_ENV,
            default=None,
            help=f"mqtt://host:port or mqtts://host:port (default: ${BROKER_ENV}, "
            f"else {DEFAULT_BROKER})",
        ),
        prefix_option,
        click.option("--username", default=None, help="broker user name"),
        click.option("--password-file", type=path, default=None, help="file holding the password"),
        click.option("--ca-file", type=path, default=None, help="CA certificate for mqtts://"),
        click.option("--cert-file", type=path, default=None, help="client certificate (mqtts://)"),
        click.option("--key-file", type=path, default=None, help="client key (mqtts://)"),
        click.option(
            "--insecure",
            is_flag=True,
            help="accept a TLS server whose certificate cannot be verified (test benches only)",
        ),
    ]
    decorated: Any = gathered
    for option in reversed(options):
        decorated = option(decorated)
    return decorated  # type: ignore[no-any-return]
