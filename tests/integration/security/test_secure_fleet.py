"""The production setup end to end: generated broker config over TLS, per-robot credentials,
signed Launch Requests; tampered, unsigned and replayed requests are rejected, brain untouched."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.launch import LaunchRequest, canonical_json, content_digest
from robotconf.contract.signing import generate_keys, load_private_key, sign
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.readmodel.retained import RetainedView
from tests.support.fleet import GitLab, Proc, pid_alive
from tests.support.lab import ROBOTCONF
from tests.support.secure import Secured, start_secured
from tests.support.watch import TIMEOUT, FleetWatch, wait_for

TOPICS = Topics()


@dataclass
class SecureFleet:
    lab: GitLab
    broker: Secured
    keys: Path
    view: FleetWatch  # as the viewer user: reads everything, writes nothing
    writer: RetainedView  # the reconciler's user, to play an attacker who stole nothing else
    agents: dict[str, Proc] = field(default_factory=dict)
    reconciler: Proc | None = None

    def status(self, robot_id: str) -> AgentStatus | None:
        return self.view.status(robot_id)

    def launch(self, robot_id: str) -> bytes:
        return self.view.retained().get(TOPICS.launch(robot_id), b"")

    def wait_running(self, requests: Mapping[str, RenderedRequest]) -> dict[str, AgentStatus]:
        return self.view.wait_running(requests)

    def send(self, robot_id: str, payload: bytes) -> None:
        assert self.writer.publish_retained([(TOPICS.launch(robot_id), payload)], TIMEOUT)

    def wait_rejected(self, robot_id: str, reason: str) -> AgentStatus:
        def probe() -> AgentStatus | None:
            status = self.status(robot_id)
            if status and status.state is AgentState.REJECTED and reason in status.message:
                return status
            return None

        return wait_for(probe, f"{robot_id} rejected: {reason}")


def _agent(fleet: SecureFleet, robot_id: str, folder: Path) -> Proc:
    work = folder / robot_id
    work.mkdir(parents=True, exist_ok=True)
    config = {
        "broker": fleet.broker.url,
        "description": {"id": robot_id, "name": robot_id},
        "command": [sys.executable, "-m", "robotconf.agent.standin_brain", "{launch_request}"],
        "workdir": str(work),
        "stop_timeout": 5,
        "startsecs": 0.2,
        "username": robot_id,
        "password_file": str(fleet.broker.secret(robot_id)),
        "tls": {"ca_file": str(fleet.broker.pki.ca_cert)},
        "public_key": str(fleet.keys / "launch-signing.pub"),
    }
    path = work / "agent.yaml"
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return Proc([str(ROBOTCONF), "agent", "--config", str(path)], work / "agent.log")


def _reconciler(fleet: SecureFleet, log: Path) -> Proc:
    return Proc(
        [
            str(ROBOTCONF), "reconcile", "--repo", str(fleet.lab.root), "--branch", "main",
            *fleet.broker.cli_args("reconciler"),
            "--signing-key", str(fleet.keys / "launch-signing.key"),
            "--interval", "300",  # no resync during a test: each repairs what it breaks
        ],
        log,
    )  # fmt: skip


@pytest.fixture(scope="module")
def secure(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SecureFleet]:
    base = tmp_path_factory.mktemp("secure-fleet")
    lab = GitLab(base / "lab")
    broker = start_secured(base, lab.root)
    keys = base / "keys"
    assert subprocess.run([ROBOTCONF, "keys", "generate", "--out", str(keys)]).returncode == 0
    view = FleetWatch(broker.connection("viewer"))
    writer = RetainedView(
        broker.connection("reconciler"), [TOPICS.all_launch], "robotconf/sync", role="attacker"
    )
    fleet = SecureFleet(lab, broker, keys, view, writer)
    try:
        writer.start()
        assert writer.wait_synced(TIMEOUT)
        for robot_id in lab.robots():
            fleet.agents[robot_id] = _agent(fleet, robot_id, base / "agents")
        fleet.reconciler = _reconciler(fleet, base / "reconciler.log")
        yield fleet
    finally:
        if fleet.reconciler is not None:
            fleet.reconciler.stop()
        for proc in fleet.agents.values():
            proc.stop()
        view.close()
        writer.stop()
        broker.server.kill()


def test_fleet_converges_over_tls_with_signed_requests(secure: SecureFleet) -> None:
    requests = secure.lab.requests()
    running = secure.wait_running(requests)
    assert set(running) == set(secure.lab.robots())
    for robot_id in running:
        published = json.loads(secure.launch(robot_id))
        assert published["signature"] and published["issued_at"]
        assert published["digest"] == requests[robot_id].digest
    done = subprocess.run(
        [str(ROBOTCONF), "status", "--repo", str(secure.lab.root), "--json",
         *secure.broker.cli_args("viewer")],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert json.loads(done.stdout)["in_sync"] is True


def test_secrets_are_never_logged_or_published(secure: SecureFleet) -> None:
    secure.wait_running(secure.lab.requests())
    secrets = [p.read_text().strip() for p in (secure.broker.out / "secrets").iterdir()]
    private_key = (secure.keys / "launch-signing.key").read_text()
    key_body = "".join(line for line in private_key.splitlines() if "PRIVATE KEY" not in line)
    published = b"".join(secure.view.retained().values()).decode("utf-8", "replace")
    texts = [published, *(proc.output() for proc in secure.agents.values())]
    assert secure.reconciler is not None
    texts.append(secure.reconciler.output())
    for work in secure.agents.values():
        texts.append(work.log.with_name("brain.log").read_text(errors="replace"))
    for text in texts:
        assert key_body not in text
        for secret in secrets:
            assert secret not in text
    # The robot's files: the workdir is private, the request readable by the agent's user only.
    for proc in secure.agents.values():
        assert proc.log.parent.stat().st_mode & 0o777 == 0o700
        assert (proc.log.parent / "launch-request.json").stat().st_mode & 0o777 == 0o600


def _brain_untouched(secure: SecureFleet, robot_id: str, before: AgentStatus) -> None:
    after = secure.status(robot_id)
    assert after is not None
    assert after.pid == before.pid and after.digest == before.digest
    assert before.pid is not None and pid_alive(before.pid)


@pytest.mark.parametrize("attack", ["unsigned", "tampered", "wrong-key"])
def test_forged_requests_are_rejected_and_the_brain_keeps_running(
    secure: SecureFleet, attack: str, tmp_path: Path
) -> None:
    robot_id = "tb3-02"
    before = secure.wait_running(secure.lab.requests())[robot_id]
    genuine = secure.launch(robot_id)
    data = json.loads(genuine)
    if attack == "unsigned":
        del data["signature"], data["issued_at"]
        reason = "not signed"
    elif attack == "tampered":
        data["robot_name"] = "Evil twin"  # digest is recomputed so only the signature can tell
        request = LaunchRequest.model_validate({**data, "signature": None, "issued_at": None})
        data["digest"] = content_digest(request.content())
        reason = "does not verify"
    else:  # signed, but by a key that is not the reconciler's
        other = generate_keys(tmp_path / "other-keys")
        forged = sign(LaunchRequest.model_validate(data), load_private_key(other.private))
        data = json.loads(forged.payload())
        reason = "does not verify"
    secure.send(robot_id, canonical_json(data))
    secure.wait_rejected(robot_id, reason)
    _brain_untouched(secure, robot_id, before)
    # The genuine request again: accepted, nothing restarts.
    secure.send(robot_id, genuine)
    wait_for(
        lambda: (s := secure.status(robot_id)) and s.state is AgentState.RUNNING,
        f"{robot_id} running again",
    )
    _brain_untouched(secure, robot_id, before)


def test_a_replayed_older_request_is_rejected(secure: SecureFleet) -> None:
    robot_id = "tb3-01"
    secure.wait_running(secure.lab.requests())
    old = secure.launch(robot_id)
    secure.lab.replace(
        "configs/scenarios/delivery-gazebo.yaml", "move_speed: 0.1", "move_speed: 0.12"
    )
    secure.lab.commit("slower delivery")
    now = secure.wait_running(secure.lab.requests())[robot_id]
    assert now.digest != json.loads(old)["digest"]
    # A validly signed request, but older than the one the robot runs: no rollback by replay.
    secure.send(robot_id, old)
    secure.wait_rejected(robot_id, "replayed request")
    _brain_untouched(secure, robot_id, now)


def test_only_a_signed_stop_stops_a_brain(secure: SecureFleet) -> None:
    """An empty retained payload, which anyone allowed on the topic can publish, stops nothing
    when signing is on; the reconciler's signed Stop does (issue 10, item 3)."""
    robot_id = "tb3-03"
    # Only this robot: earlier tests leave others rejected on purpose.
    before = secure.wait_running({robot_id: secure.lab.requests()[robot_id]})[robot_id]
    genuine = secure.launch(robot_id)
    secure.send(robot_id, b"")
    secure.wait_rejected(robot_id, "unsigned stop refused")
    _brain_untouched(secure, robot_id, before)
    secure.send(robot_id, genuine)
    wait_for(
        lambda: (s := secure.status(robot_id)) and s.state is AgentState.RUNNING,
        f"{robot_id} running again",
    )
    # The reconciler unassigns the robot: its signed Stop is obeyed.
    secure.lab.replace("configs/fleet.yaml", "  tb3-03: {", "  # tb3-03: {")
    secure.lab.commit("tb3-03 leaves the fleet")
    wait_for(
        lambda: (s := secure.status(robot_id)) and s.state is AgentState.IDLE,
        f"{robot_id} idle after the signed stop",
    )
    assert before.pid is not None and not pid_alive(before.pid)
    assert json.loads(secure.launch(robot_id))["kind"] == "Stop"


def test_requests_published_before_signing_was_on_are_signed_when_it_is(
    secure: SecureFleet, tmp_path: Path
) -> None:
    """A lab turns signing on: the reconciler starts with --signing-key over requests it
    published unsigned, their digests unchanged. It publishes each again, signed, and the robot
    that refused the unsigned one runs it, not restarted; without this it stayed `rejected`
    until its next change. The writer stands in for the reconciler that ran without the key."""
    robot_id = "tb3-02"
    before = secure.wait_running({robot_id: secure.lab.requests()[robot_id]})[robot_id]
    assert secure.reconciler is not None
    secure.reconciler.stop()
    data = json.loads(secure.launch(robot_id))
    del data["signature"], data["issued_at"]
    secure.send(robot_id, canonical_json(data))
    secure.wait_rejected(robot_id, "not signed")
    secure.reconciler = _reconciler(secure, tmp_path / "reconciler.log")
    wait_for(
        lambda: (s := secure.status(robot_id)) and s.state is AgentState.RUNNING,
        f"{robot_id} running its request again, signed",
    )
    _brain_untouched(secure, robot_id, before)
    published = json.loads(secure.launch(robot_id))
    assert published["signature"] and published["digest"] == data["digest"]
