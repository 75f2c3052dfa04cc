"""Which failed connection attempts a desk command reports at once (the network answered) and
which it waits out (a silence)."""

from __future__ import annotations

import errno
import socket
import ssl

import pytest

from robotconf.contract.mqtt import NOTHING_LISTENS, connect_failure


def test_a_refused_connection_is_nothing_listening() -> None:
    assert connect_failure(ConnectionRefusedError(errno.ECONNREFUSED, "refused")) == NOTHING_LISTENS


@pytest.mark.parametrize("error", [ConnectionResetError, ConnectionAbortedError, BrokenPipeError])
def test_a_connection_cut_by_the_other_side_is_said(error: type[OSError]) -> None:
    assert connect_failure(error()) == "the connection was reset"


def test_a_failed_tls_handshake_names_why() -> None:
    failed = ssl.SSLCertVerificationError(1, "certificate verify failed")
    failed.verify_message = "self-signed certificate"
    assert connect_failure(failed) == "TLS handshake failed: self-signed certificate"


def test_an_unknown_host_is_said_but_a_silent_resolver_is_waited_out() -> None:
    unknown = socket.gaierror(socket.EAI_NONAME, "Name or service not known")
    assert connect_failure(unknown) == "unknown host (Name or service not known)"
    assert connect_failure(socket.gaierror(socket.EAI_AGAIN, "Temporary failure")) is None


def test_an_unreachable_network_is_said() -> None:
    assert connect_failure(OSError(errno.EHOSTUNREACH, "x")) == "no route to host"
    assert connect_failure(OSError(errno.ENETUNREACH, "x")) == "network unreachable"


@pytest.mark.parametrize(
    "error",
    [TimeoutError(), OSError(errno.ETIMEDOUT, "x"), OSError(errno.EINVAL, "x"), ValueError(), None],
)
def test_a_silence_or_anything_else_is_waited_out(error: BaseException | None) -> None:
    assert connect_failure(error) is None
