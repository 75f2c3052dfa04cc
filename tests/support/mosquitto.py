"""A real Mosquitto broker for tests: its own config on a free port, restartable, always killed.

Shared by every suite that talks MQTT; never replace it with a mock.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path

START_TIMEOUT = 10.0


def find_mosquitto() -> str | None:
    found = shutil.which("mosquitto")
    if found:
        return found
    for candidate in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto"):
        if os.access(candidate, os.X_OK):
            return candidate
    return None


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


class Mosquitto:
    """`mosquitto -c <own config>` in `workdir`; `stop()` then `start()` keeps the port."""

    def __init__(
        self,
        workdir: Path,
        binary: str | None = None,
        persistence: bool = False,
        listener_options: Sequence[str] = (),
        allow_anonymous: bool = True,
        extra_config: Sequence[str] = (),
    ) -> None:
        found = binary or find_mosquitto()
        if found is None:
            raise RuntimeError(
                "mosquitto not found on PATH or in /usr/sbin; `./dev setup` installs it"
            )
        self.binary = found
        self.workdir = workdir
        self.persistence = persistence
        self.listener_options = list(listener_options)  # e.g. certfile, password_file lines
        self.allow_anonymous = allow_anonymous
        self.extra_config = list(extra_config)  # after everything else, e.g. a bridge section
        self.host = "127.0.0.1"
        self.port = 0
        self.proc: subprocess.Popen[bytes] | None = None
        self.log_path = workdir / "mosquitto.log"

    @property
    def url(self) -> str:
        return f"mqtt://{self.host}:{self.port}"

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def _write_config(self) -> Path:
        conf = self.workdir / "mosquitto.conf"
        lines = [
            f"listener {self.port} {self.host}",
            *self.listener_options,
            f"allow_anonymous {'true' if self.allow_anonymous else 'false'}",
            f"persistence {'true' if self.persistence else 'false'}",
            f"persistence_location {self.workdir}/",
            "log_dest stderr",
            "log_type error",
            "log_type warning",
            "log_type notice",
            "log_type information",
            "connection_messages true",
        ]
        if os.geteuid() == 0:
            # As root Mosquitto would switch to the `mosquitto` user, who cannot read or write
            # the test's private temporary folders.
            lines.append("user root")
        # Last: a bridge's `connection` line starts a section that runs to the end of the file.
        lines += self.extra_config
        conf.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return conf

    def start(self) -> None:
        if self.running:
            return
        self.workdir.mkdir(parents=True, exist_ok=True)
        # A first start may lose its free port to a race; a restart must keep its port.
        attempts = 3 if self.port == 0 else 1
        last_error = ""
        for _ in range(attempts):
            if self.port == 0 or attempts > 1:
                self.port = free_port()
            conf = self._write_config()
            log = self.log_path.open("ab")
            try:
                self.proc = subprocess.Popen(
                    [self.binary, "-c", str(conf)],
                    stdout=log,
                    stderr=log,
                    stdin=subprocess.DEVNULL,
                    start_new_session=True,
                )
            finally:
                log.close()
            if self._wait_accepting():
                return
            last_error = self.log_tail()
            self.kill()
        raise RuntimeError(f"mosquitto did not start on port {self.port}:\n{last_error}")

    def _wait_accepting(self) -> bool:
        deadline = time.monotonic() + START_TIMEOUT
        while time.monotonic() < deadline:
            if not self.running:
                return False
            with (
                contextlib.suppress(OSError),
                socket.create_connection((self.host, self.port), timeout=0.5),
            ):
                return True
            time.sleep(0.05)
        return False

    def stop(self) -> None:
        """A graceful stop (SIGTERM): Mosquitto saves its retained messages if persistent."""
        self._end(signal.SIGTERM)

    def kill(self) -> None:
        """An abrupt stop (SIGKILL), like a crashed or powered-off broker."""
        self._end(signal.SIGKILL)

    def _end(self, sig: signal.Signals) -> None:
        proc = self.proc
        if proc is None:
            return
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(sig)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.proc = None

    def restart(self) -> None:
        self.stop()
        self.start()

    def log_tail(self, lines: int = 40) -> str:
        try:
            text = self.log_path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def __enter__(self) -> Mosquitto:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()
