"""A whole-fleet reader on a real Mosquitto: the queue broker-config sets holds a large fleet's
retained messages, and a queue that drops them is reported, never read as robots Offline."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from robotconf.configurator.brokerconf import Listener, render_conf
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import AgentState, AgentStatus, Topics
from robotconf.workstation.fleet_status import open_view
from tests.support.fleet import robotconf_argv
from tests.support.lab import ROOT
from tests.support.mosquitto import Mosquitto

sys.path.insert(0, str(ROOT / "bench"))
import generate

TOPICS = Topics()


def queue_settings(robots: int) -> list[str]:
    """The generated config's global settings (its listeners are the test's own)."""
    conf = render_conf(Listener(), 8884, Path("/etc/mosquitto/robotconf"), robots)
    return [line for line in conf.splitlines() if line.startswith("max_queued")]


@pytest.fixture
def broker_with(tmp_path: Path) -> Iterator[list[Mosquitto]]:
    started: list[Mosquitto] = []
    yield started
    for broker in started:
        broker.kill()


def start(started: list[Mosquitto], folder: Path, settings: list[str]) -> Mosquitto:
    broker = Mosquitto(folder, extra_config=settings)
    broker.start()
    started.append(broker)
    return broker


def publish_all(url: str, items: list[tuple[str, bytes]]) -> None:
    client = make_client(Connection(url), "test-fleet-publisher")
    client.max_inflight_messages_set(0)
    client.connect("127.0.0.1", Connection(url).address.port)
    client.loop_start()
    try:
        infos = [client.publish(t, p, qos=1, retain=True) for t, p in items]
        for info in infos:
            info.wait_for_publish(30)
            assert info.is_published()
    finally:
        client.disconnect()
        client.loop_stop()


def fleet_messages(robots: int) -> list[tuple[str, bytes]]:
    """Request- and report-sized retained messages on every robot topic a reader reads."""
    items: list[tuple[str, bytes]] = []
    for n in range(robots):
        robot = f"r{n:05d}"
        status = AgentStatus(robot_id=robot, state=AgentState.RUNNING).model_dump_json()
        items += [
            (TOPICS.launch(robot), b"L" * 3000),
            (TOPICS.status(robot), status.encode()),
            (TOPICS.description(robot), b"D" * 2000),
            (TOPICS.interfaces(robot), b"I" * 5000),
            (TOPICS.goals(robot), b"G" * 2000),
        ]
    return items


@pytest.mark.parametrize("generated", [True, False], ids=["generated", "default"])
def test_the_generated_queue_delivers_a_large_fleet_to_a_whole_fleet_reader(
    broker_with: list[Mosquitto], tmp_path: Path, generated: bool
) -> None:
    robots = 2500
    settings = queue_settings(robots) if generated else []
    broker = start(broker_with, tmp_path / "broker", settings)
    items = fleet_messages(robots)
    publish_all(broker.url, items)
    view = open_view(Connection(broker.url), TOPICS.prefix)
    view.start()
    try:
        assert view.wait_synced(30)
        got = view.snapshot()
        view.confirm_missing([t for t, _ in items], 10)
    finally:
        view.stop()
    if generated:
        assert settings == ["max_queued_messages 26000"]
        assert len(got) == len(items) and view.lost is None
    else:  # Mosquitto's default of 1,000: the reader is told, whatever it got
        assert len(got) < len(items) and view.lost is not None, len(got)


def status_json(lab: Path, url: str) -> dict[str, object]:
    done = subprocess.run(
        robotconf_argv("status", "--repo", str(lab), "--broker", url, "--json"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stderr, done.stderr
    found: dict[str, object] = json.loads(done.stdout)
    return found


@pytest.mark.parametrize("tiny", [True, False], ids=["tiny-queue", "generated"])
def test_status_reports_dropped_messages_instead_of_offline_robots(
    broker_with: list[Mosquitto], tmp_path: Path, tiny: bool
) -> None:
    lab = tmp_path / "lab"
    generate.generate(lab, generate.Sizes(robots=100, scenarios=20), use_git=False)
    robots = sorted(_fleet_robots(lab))
    settings = ["max_queued_messages 10"] if tiny else queue_settings(len(robots))
    broker = start(broker_with, tmp_path / "broker", settings)
    items: list[tuple[str, bytes]] = []
    for robot in robots:
        # Launch topics are sent first: 15 MB of them fill the socket's buffers, then the
        # queue of 10, and the statuses that follow are dropped.
        status = AgentStatus(robot_id=robot, state=AgentState.RUNNING).model_dump_json()
        items += [
            (TOPICS.launch(robot), b"{" + b" " * 150_000),
            (TOPICS.status(robot), status.encode()),
        ]
    publish_all(broker.url, items)
    found = status_json(lab, broker.url)
    verdicts = {r["robot_id"]: r["verdict"] for r in found["robots"]}  # type: ignore[attr-defined]
    assert set(verdicts) >= set(robots)
    assert "Offline" not in verdicts.values()
    if tiny:
        assert "Unknown" in verdicts.values()
        said = str(found["broker_dropped"])
        assert "the broker dropped retained messages" in said and "max_queued_messages" in said
    else:
        assert found["broker_dropped"] is None and "Unknown" not in verdicts.values()


def _fleet_robots(lab: Path) -> list[str]:
    fleet = yaml.safe_load((lab / "configs/fleet.yaml").read_text(encoding="utf-8"))
    return [r for r, entry in fleet["robots"].items() if not entry.get("suspended")]
