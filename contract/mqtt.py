"""One way to build a paho-mqtt 2.x client (callback API v2) from a broker URL and credentials.

Shared by the agent, the reconciler and `robotconf status`; MQTT 3.1.1 by default so that any
broker (Mosquitto, the embedded amqtt of `robotconf up`) serves it.
"""

from __future__ import annotations

import errno
import socket
import ssl
from dataclasses import dataclass
from pathlib import Path

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from robotconf.contract.trust import Trust, check_trusted, read_secret_text
from robotconf.contract.wire import BrokerAddress, parse_broker_url

# Seconds between connection attempts: the first retry after 1 s, doubling up to 30 s. paho's
# own loop uses them for the reconciler and `status`; the agent, driving paho itself, feeds
# them to contract.backoff.Backoff.
RECONNECT_MIN_DELAY, RECONNECT_MAX_DELAY = 1.0, 30.0


@dataclass(frozen=True)
class Connection:
    """Where and how to connect; secrets are read from files, never passed on a command line."""

    url: str
    username: str | None = None
    password_file: Path | None = None
    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None
    insecure: bool = False  # skip server certificate verification (tests, lab benches only)
    protocol: MQTTProtocolVersion = MQTTProtocolVersion.MQTTv311

    @property
    def address(self) -> BrokerAddress:
        return parse_broker_url(self.url)

    def password(self) -> str | None:
        if self.password_file is None:
            return self.address.password
        # A secret: refused when others may read or change it (contract/trust.py).
        return read_secret_text(self.password_file)


MAX_TLS_FILE = 1024 * 1024  # a certificate chain; anything larger is not one


def check_tls_files(connection: Connection) -> None:
    """UntrustedFile (an OSError) when a TLS file is one others could have changed, or the key
    one others may read; ssl reads them by path afterwards. A certificate file without a key
    file holds the key too: a secret then."""
    key_in_cert = connection.key_file is None
    for path, kind in (
        (connection.ca_file, Trust.CONFIG),
        (connection.cert_file, Trust.SECRET if key_in_cert else Trust.CONFIG),
        (connection.key_file, Trust.SECRET),
    ):
        if path is not None:
            check_trusted(path, kind, MAX_TLS_FILE)


def make_client(connection: Connection, client_id: str, *, session: bool = False) -> paho.Client:
    """A configured, not yet connected client. `session` (MQTT 3.1.1): a persistent session,
    the broker keeps the client's subscriptions and queues its QoS 1 messages while it is away
    (the ledger's feed); its client id must then be the same at every start."""
    address = connection.address
    v5 = connection.protocol == MQTTProtocolVersion.MQTTv5
    client = paho.Client(
        CallbackAPIVersion.VERSION2,
        client_id=client_id,
        protocol=connection.protocol,
        clean_session=None if v5 else not session,
    )
    username = connection.username or address.username
    if username:
        client.username_pw_set(username, connection.password())
    if address.tls:
        check_tls_files(connection)
        context = ssl.create_default_context(
            cafile=str(connection.ca_file) if connection.ca_file else None
        )
        if connection.cert_file:
            context.load_cert_chain(
                str(connection.cert_file),
                str(connection.key_file) if connection.key_file else None,
            )
        if connection.insecure:
            context.check_hostname = False
            context.verify_mode = ssl.CERT_NONE
        client.tls_set_context(context)
    client.reconnect_delay_set(
        min_delay=int(RECONNECT_MIN_DELAY), max_delay=int(RECONNECT_MAX_DELAY)
    )
    return client


# Errors of a connection attempt that the network answered: trying again within a desk
# command's wait would meet the same answer. A timeout is not among them (a silent network).
NOTHING_LISTENS = "connection refused: nothing listens on that port"
_UNREACHABLE = {errno.ENETUNREACH: "network unreachable", errno.EHOSTUNREACH: "no route to host"}


def connect_failure(exc: BaseException | None) -> str | None:
    """Why a connection attempt failed, in words, when the broker's side answered it at once
    (refused, reset, closed, an unknown host, a TLS handshake it failed); None for a silence
    (a timeout) or anything else, which only waiting can tell."""
    if isinstance(exc, ConnectionRefusedError):
        return NOTHING_LISTENS
    if isinstance(exc, (ConnectionResetError, ConnectionAbortedError, BrokenPipeError)):
        return "the connection was reset"
    if isinstance(exc, ssl.SSLError):
        why = getattr(exc, "verify_message", None) or exc.reason or exc
        return f"TLS handshake failed: {why}"
    if isinstance(exc, socket.gaierror):
        if exc.errno == socket.EAI_AGAIN:  # the resolver did not answer: a silence
            return None
        return f"unknown host ({exc.strerror})"
    if isinstance(exc, OSError) and exc.errno in _UNREACHABLE:
        return _UNREACHABLE[exc.errno]
    return None
