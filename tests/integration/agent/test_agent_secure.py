"""The agent against a locked-down Mosquitto: TLS, a client certificate, a password, signatures."""

from __future__ import annotations

import datetime
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from robotconf.contract.mqtt import Connection
from robotconf.contract.signing import generate_keys, load_private_key, sign
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import AgentProc, make_request, publish
from tests.support.mosquitto import Mosquitto
from tests.support.private import write_private
from tests.support.tlsutil import make_pki
from tests.support.watch import FleetWatch, wait_for

ROBOT = "tb3-01"
LAUNCH = Topics().launch(ROBOT)


def _name(common: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common)])


def make_client_cert(folder: Path, user: str) -> tuple[Path, Path, Path]:
    """(client CA, client certificate, client key): the broker trusts that CA for clients."""
    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = (
        x509.CertificateBuilder()
        .subject_name(_name("robotconf test client CA"))
        .issuer_name(_name("robotconf test client CA"))
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(ca_key, hashes.SHA256())
    )
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(user))
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .sign(ca_key, hashes.SHA256())
    )
    paths = (folder / "client-ca.crt", folder / "client.crt", folder / "client.key")
    paths[0].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    paths[1].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    paths[2].write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    paths[2].chmod(0o600)
    return paths


@dataclass
class Secured:
    broker: Mosquitto
    server_ca: Path
    client_cert: Path
    client_key: Path
    password_file: Path
    keys: Path

    def connection(self) -> Connection:
        return Connection(
            url=f"mqtts://127.0.0.1:{self.broker.port}",
            username=ROBOT,
            password_file=self.password_file,
            ca_file=self.server_ca,
            cert_file=self.client_cert,
            key_file=self.client_key,
        )

    def agent_settings(self) -> dict[str, Any]:
        return {
            "broker": f"mqtts://127.0.0.1:{self.broker.port}",
            "username": ROBOT,
            "password_file": str(self.password_file),
            "tls": {
                "ca_file": str(self.server_ca),
                "cert_file": str(self.client_cert),
                "key_file": str(self.client_key),
            },
            "public_key": str(self.keys / "launch-signing.pub"),
        }


@pytest.fixture
def secured(tmp_path: Path) -> Iterator[Secured]:
    pki = make_pki(tmp_path / "pki")
    client_ca, client_cert, client_key = make_client_cert(tmp_path / "pki", ROBOT)
    passwd = tmp_path / "passwd"
    subprocess.run(["mosquitto_passwd", "-c", "-b", str(passwd), ROBOT, "s3cret"], check=True)
    password_file = tmp_path / "robot.password"
    password_file.write_text("s3cret\n", encoding="utf-8")
    password_file.chmod(0o600)
    broker = Mosquitto(
        tmp_path / "broker",
        listener_options=[
            f"certfile {pki.server_cert}",
            f"keyfile {pki.server_key}",
            f"cafile {client_ca}",
            "require_certificate true",
            f"password_file {passwd}",
        ],
        allow_anonymous=False,
    )
    keys = tmp_path / "keys"
    generate_keys(keys)
    broker.start()
    try:
        yield Secured(broker, pki.ca_cert, client_cert, client_key, password_file, keys)
    finally:
        broker.kill()


def test_tls_client_certificate_password_and_signed_requests(
    tmp_path: Path, secured: Secured
) -> None:
    watch = FleetWatch(secured.connection())
    agent = AgentProc(tmp_path / "agent", "unused", **secured.agent_settings())
    try:
        agent.start()
        watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
        wait_for(lambda: watch.description(ROBOT), "the description over TLS")

        unsigned = make_request()
        publish(secured.connection(), LAUNCH, unsigned.payload())
        watch.wait_for(
            ROBOT,
            lambda s: s.state == AgentState.REJECTED and "not signed" in s.message,
            "an unsigned request to be refused",
            agent=agent,
        )
        foreign = generate_keys(tmp_path / "other-keys")
        forged = sign(make_request(variant=1), load_private_key(foreign.private))
        publish(secured.connection(), LAUNCH, forged.payload())
        watch.wait_for(
            ROBOT,
            lambda s: s.state == AgentState.REJECTED and "does not verify" in s.message,
            "a request signed by another key to be refused",
            agent=agent,
        )
        our_key = load_private_key(secured.keys / "launch-signing.key")
        signed = sign(make_request(variant=2), our_key)
        publish(secured.connection(), LAUNCH, signed.payload())
        running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=signed.digest)
        agent.note_brain(running.pid)
    finally:
        watch.close()
        agent.cleanup()


def test_wrong_password_is_reported_and_retried(tmp_path: Path, secured: Secured) -> None:
    wrong = tmp_path / "wrong.password"
    write_private(wrong, "guess\n")
    settings = secured.agent_settings() | {"password_file": str(wrong)}
    agent = AgentProc(tmp_path / "agent", "unused", **settings)
    try:
        agent.start()
        wait_for(
            lambda: "broker refused the connection" in agent.log_tail(), "the refusal in the log"
        )
        assert agent.proc is not None and agent.proc.poll() is None  # still trying
    finally:
        agent.cleanup()


def refused_as_ahead(watch: FleetWatch, agent: AgentProc) -> AgentStatus:
    """The status that refuses a signed request as dated ahead of the robot's clock."""
    return watch.wait_for(
        ROBOT,
        lambda s: s.state == AgentState.REJECTED and "ahead of this robot's clock" in s.message,
        "the request refused as dated ahead",
        agent=agent,
    )


def test_a_request_refused_as_dated_ahead_runs_once_the_robot_s_clock_reaches_it(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    """A retained request is not sent again: refused for a date a few seconds too far ahead
    (a reconciler's clock slightly fast), the agent looks at it again once its own clock has
    caught up, and runs it without another publish."""
    keys = generate_keys(tmp_path / "keys")
    private = load_private_key(keys.private)
    agent = make_agent(public_key=str(keys.public)).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    ahead = sign(make_request(variant=1), private, issued_at=time.time() + 34)  # 4 s too far
    publish(mosquitto.url, LAUNCH, ahead.payload())
    refused = refused_as_ahead(watch, agent)
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=ahead.digest)
    agent.note_brain(running.pid)
    assert "check NTP" in refused.message and running.pid is not None
    assert agent.brain_log().count("ahead of this robot's clock") == 1  # said once


def test_a_fast_reconcilers_request_is_refused_and_locks_nothing_out(
    mosquitto: Mosquitto, watch: FleetWatch, make_agent: AgentFactory, tmp_path: Path
) -> None:
    """A signed request dated an hour ahead of the robot's clock is refused (it would have
    set the replay watermark an hour ahead); the next one, from a correct clock, runs; and a
    replay of an accepted request is still refused, across an agent restart too."""
    keys = generate_keys(tmp_path / "keys")
    private = load_private_key(keys.private)
    agent = make_agent(public_key=str(keys.public)).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    first = sign(make_request(variant=1), private)
    publish(mosquitto.url, LAUNCH, first.payload())
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=first.digest)
    fast = sign(make_request(variant=2), private, issued_at=time.time() + 3600)
    publish(mosquitto.url, LAUNCH, fast.payload())
    refused = refused_as_ahead(watch, agent)
    assert "check NTP" in refused.message
    correct = sign(make_request(variant=3), private)
    publish(mosquitto.url, LAUNCH, correct.payload())
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=correct.digest)
    agent.note_brain(running.pid)
    agent.signal(signal.SIGKILL)  # the watermark is on disk: a restart forgets nothing
    agent.wait()
    agent.start()
    watch.wait_for(ROBOT, lambda s: s.seq > running.seq, "the agent back", agent=agent)
    publish(mosquitto.url, LAUNCH, first.payload())
    watch.wait_for(
        ROBOT,
        lambda s: s.state == AgentState.REJECTED and "replayed request" in s.message,
        "the replayed request refused",
        agent=agent,
    )
