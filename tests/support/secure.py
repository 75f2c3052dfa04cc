"""A Mosquitto run with the configuration `robotconf broker-config` generates (ACL, passwords,
TLS with a test CA), and connections to it as a given user."""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

from robotconf.configurator.types import SERVICE_USERS
from robotconf.contract.mqtt import Connection
from tests.support.lab import ROBOTCONF
from tests.support.mosquitto import Mosquitto, free_port
from tests.support.tlsutil import Pki, make_pki


class SecuredMosquitto(Mosquitto):
    """Mosquitto with the generated configuration; only the listener's port is the test's."""

    def __init__(self, workdir: Path, generated: Path) -> None:
        super().__init__(workdir)
        self.generated = generated
        self.service_port = free_port()  # the reconciler's and viewers' listener

    def _write_config(self) -> Path:
        conf = self.workdir / "mosquitto.conf"
        lines = []
        ports = iter([self.port, self.service_port])
        for line in self.generated.read_text(encoding="utf-8").splitlines():
            if line.startswith("listener "):
                line = f"listener {next(ports)} {self.host}"
            lines.append(line)
        # Started as root, Mosquitto would drop to the `mosquitto` user, which cannot read the
        # test's 0600 files; a real deployment chowns them to that user instead.
        lines += ["user root", "persistence false", "log_dest stderr", "log_type all"]
        conf.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return conf


@dataclass
class Secured:
    server: SecuredMosquitto
    out: Path
    pki: Pki

    @property
    def url(self) -> str:
        """Where robots connect."""
        return f"mqtts://127.0.0.1:{self.server.port}"

    @property
    def service_url(self) -> str:
        """Where the reconciler and viewers connect."""
        return f"mqtts://127.0.0.1:{self.server.service_port}"

    def url_for(self, user: str | None) -> str:
        return self.service_url if user in SERVICE_USERS else self.url

    def secret(self, user: str) -> Path:
        return self.out / "secrets" / f"{user}.password"

    def connection(
        self, user: str | None, *, password_file: Path | None = None, url: str | None = None
    ) -> Connection:
        return Connection(
            url=url or self.url_for(user),
            username=user,
            password_file=password_file or (self.secret(user) if user else None),
            ca_file=self.pki.ca_cert,
        )

    def cli_args(self, user: str) -> list[str]:
        """`--broker ... --username ... --password-file ... --ca-file ...` for robotconf."""
        return [
            "--broker", self.url_for(user),
            "--username", user,
            "--password-file", str(self.secret(user)),
            "--ca-file", str(self.pki.ca_cert),
        ]  # fmt: skip


def start_secured(base: Path, repo: Path) -> Secured:
    """broker-config for the repository's fleet, then Mosquitto with it."""
    pki = make_pki(base / "pki")
    out = base / "broker"
    done = subprocess.run(
        [
            ROBOTCONF, "broker-config", "--repo", str(repo), "--out", str(out),
            "--certfile", str(pki.server_cert), "--keyfile", str(pki.server_key),
            "--bind", "127.0.0.1",
        ],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for secret in (out / "secrets").iterdir():  # secrets are never printed
        assert secret.read_text().strip() not in done.stdout + done.stderr
        assert secret.stat().st_mode & 0o077 == 0
    server = SecuredMosquitto(base / "run", out / "mosquitto.conf")
    server.start()
    return Secured(server, out, pki)
