"""The documented production example stays true: current with the fleet, and a valid agent.yaml."""

from __future__ import annotations

import subprocess
from pathlib import Path

from agent.config import load_config
from tests.support.lab import ROBOTCONF, ROOT

EXAMPLE = ROOT / "examples" / "production"


def test_example_broker_files_are_what_broker_config_writes(tmp_path: Path) -> None:
    out = tmp_path / "broker"
    done = subprocess.run(
        [
            ROBOTCONF, "broker-config", "--repo", str(ROOT), "--out", str(out),
            "--install-dir", "/etc/mosquitto/robotconf",
            "--certfile", "/etc/mosquitto/certs/server.crt",
            "--keyfile", "/etc/mosquitto/certs/server.key",
        ],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for name in ("acl", "mosquitto.conf"):
        assert (out / name).read_text() == (EXAMPLE / name).read_text(), (
            f"examples/production/{name} is stale: regenerate it (see its README)"
        )
    assert not (EXAMPLE / "passwd").exists() and not (EXAMPLE / "secrets").exists()


def test_example_agent_yaml_is_valid(tmp_path: Path) -> None:
    text = (EXAMPLE / "agent.yaml").read_text(encoding="utf-8")
    folder = tmp_path / "etc"
    folder.mkdir()
    # The referenced files and workdir exist on a robot; stand them in here.
    (folder / "tb3-01.password").write_text("secret\n")
    (folder / "ca.crt").write_text("")
    subprocess.run([ROBOTCONF, "keys", "generate", "--out", str(folder)], check=True)
    text = text.replace("/var/lib/robotconf/tb3-01", str(tmp_path / "work"))
    (folder / "agent.yaml").write_text(text, encoding="utf-8")
    config = load_config(folder / "agent.yaml")
    assert config.public_key == folder / "launch-signing.pub"
    assert config.connection().address.tls
