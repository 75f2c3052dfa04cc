"""Where the UI may listen: loopback as it likes; any other address only with an operator token
and TLS, served here (--tls-cert/--tls-key) or by a reverse proxy said to terminate it."""

from __future__ import annotations

import ipaddress
import ssl
from dataclasses import dataclass
from pathlib import Path

from contract.errors import CliError, ExitCode

DEFAULT_LISTEN = "127.0.0.1:8765"


@dataclass(frozen=True)
class Listen:
    host: str
    port: int

    @property
    def loopback(self) -> bool:
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False  # a name: whatever it resolves to, it is not known to be loopback

    @property
    def url_host(self) -> str:
        return f"[{self.host}]" if ":" in self.host else self.host


def parse_listen(text: str) -> Listen:
    """HOST:PORT ([v6]:PORT for IPv6); CliError otherwise."""
    host, colon, port = text.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not colon or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise CliError(f"--listen {text!r} is not HOST:PORT (e.g. {DEFAULT_LISTEN})")
    return Listen(host, int(port))


def check_exposure(
    listen: Listen,
    token_file: Path | None,
    tls_cert: Path | None,
    tls_key: Path | None,
    behind_tls_proxy: bool,
) -> None:
    """CliError (exit 2) when the UI would listen beyond this machine unprotected: without an
    operator token, or without TLS here or a proxy's; or when TLS is half given."""
    if (tls_cert is None) != (tls_key is None):
        raise CliError("--tls-cert and --tls-key go together", ExitCode.TOOL)
    if tls_cert is not None and behind_tls_proxy:
        raise CliError(
            "--behind-tls-proxy says a proxy terminates TLS: give it or --tls-cert, not both",
            ExitCode.TOOL,
        )
    if listen.loopback:
        return
    where = f"--listen {listen.url_host}:{listen.port} is reachable from other machines"
    if token_file is None:
        raise CliError(
            f"{where}: give --operator-token-file too, so that only operators act",
            ExitCode.TOOL,
        )
    if tls_cert is None and not behind_tls_proxy:
        raise CliError(
            f"{where}: serve it over TLS (--tls-cert F --tls-key F), or say that a reverse "
            "proxy terminates TLS in front of it (--behind-tls-proxy)",
            ExitCode.TOOL,
        )


def tls_context(cert: Path, key: Path) -> ssl.SSLContext:
    """The server's TLS context (TLS 1.2 at least); CliError when the files do not load."""
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        context.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError) as exc:
        reason = getattr(exc, "strerror", None) or getattr(exc, "reason", None) or str(exc)
        raise CliError(f"cannot load --tls-cert {cert} / --tls-key {key}: {reason}") from None
    return context
