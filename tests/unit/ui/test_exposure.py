"""Where the UI may listen: loopback freely, elsewhere only with a token and TLS (its own or a
proxy's)."""

from __future__ import annotations

from pathlib import Path

import pytest

from contract.errors import CliError, ExitCode
from workstation.ui.exposure import Listen, check_exposure, parse_listen, tls_context

TOKEN = Path("token")
CERT = Path("cert.pem")
KEY = Path("key.pem")


@pytest.mark.parametrize(
    ("text", "host", "port", "loopback"),
    [
        ("127.0.0.1:8765", "127.0.0.1", 8765, True),
        ("127.8.9.10:1", "127.8.9.10", 1, True),
        ("localhost:80", "localhost", 80, True),
        ("[::1]:8765", "::1", 8765, True),
        ("0.0.0.0:8765", "0.0.0.0", 8765, False),
        ("[::]:8765", "::", 8765, False),
        ("192.168.1.5:0", "192.168.1.5", 0, False),
        ("lab.example:443", "lab.example", 443, False),
    ],
)
def test_listen_addresses(text: str, host: str, port: int, loopback: bool) -> None:
    listen = parse_listen(text)
    assert listen == Listen(host, port) and listen.loopback is loopback


@pytest.mark.parametrize("text", ["8765", ":8765", "host:", "host:http", "host:70000", ""])
def test_a_listen_that_is_not_host_port_is_refused(text: str) -> None:
    with pytest.raises(CliError, match="HOST:PORT"):
        parse_listen(text)


def test_loopback_needs_nothing() -> None:
    check_exposure(parse_listen("127.0.0.1:8765"), None, None, None, False)


def test_elsewhere_needs_a_token_and_tls_or_a_proxy() -> None:
    anywhere = parse_listen("0.0.0.0:8765")
    with pytest.raises(CliError, match="--operator-token-file") as refused:
        check_exposure(anywhere, None, CERT, KEY, False)
    assert refused.value.code == ExitCode.TOOL
    with pytest.raises(CliError, match="--behind-tls-proxy"):
        check_exposure(anywhere, TOKEN, None, None, False)
    check_exposure(anywhere, TOKEN, CERT, KEY, False)
    check_exposure(anywhere, TOKEN, None, None, True)
    with pytest.raises(CliError, match="go together"):
        check_exposure(anywhere, TOKEN, CERT, None, False)
    with pytest.raises(CliError, match="not both"):
        check_exposure(anywhere, TOKEN, CERT, KEY, True)


def test_tls_files_that_do_not_load_are_one_clear_error(tmp_path: Path) -> None:
    (tmp_path / "cert.pem").write_text("not a certificate\n", encoding="utf-8")
    with pytest.raises(CliError, match="cannot load --tls-cert"):
        tls_context(tmp_path / "cert.pem", tmp_path / "cert.pem")
    with pytest.raises(CliError, match="cannot load --tls-cert"):
        tls_context(tmp_path / "missing.pem", tmp_path / "missing.pem")
