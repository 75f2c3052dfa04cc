"""The control loop against a real Mosquitto, without agents: what ends up on the launch topics."""

from __future__ import annotations

from pathlib import Path

from robotconf.contract.mqtt import Connection
from robotconf.readmodel.retained import RetainedView
from robotconf.reconciler.source import LocalBranch, RemoteBranch
from tests.support.fleet import ROBOTS, GitLab, Running
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for


def published(watch: FleetWatch, lab: GitLab, revision: str) -> bool:
    """The launch topics hold exactly the requests of `revision`."""
    requests = lab.requests(revision)
    digests = {r: (watch.launch(r) or {}).get("digest") for r in set(requests) | set(ROBOTS)}
    return digests == {r: (requests[r].digest if r in requests else None) for r in digests}


def test_a_commit_that_empties_the_fleet_is_refused_unless_allowed(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url)
    try:
        good = lab.head()
        wait_for(lambda: published(watch, lab, good), "the lab published")
        lab.write("configs/fleet.yaml", "robots: {}\n")
        empty = lab.commit("oops: nobody assigned")
        status = watch.wait_reconciler(lambda s: s.last_attempted_revision == empty, "attempted")
        assert status.state == "Stalled" and status.last_applied_revision == good
        assert any("allow_empty" in d for d in map(str, status.diagnostics))
        assert published(watch, lab, good)

        lab.write("configs/fleet.yaml", "robots: {}\nallow_empty: true\n")
        allowed = lab.commit("really empty the lab")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == allowed, "applied")
        wait_for(lambda: all(watch.launch(r) is None for r in ROBOTS), "every topic cleared")
    finally:
        running.stop()


def test_suspended_robots_keep_what_they_have(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url)
    try:
        first = lab.head()
        wait_for(lambda: published(watch, lab, first), "the lab published")
        before = watch.launch("tb3-02")
        lab.replace(
            "configs/fleet.yaml",
            "tb3-02: {scenario: guide-gazebo, name: Guide bot",
            "tb3-02: {scenario: patrol-real, name: Guide bot, suspended: true",
        )
        lab.replace("configs/fleet.yaml", "Lab patrol", "Lab patroller")
        head = lab.commit("suspend the guide while renaming the patrol")
        watch.wait_reconciler(lambda s: s.last_applied_revision == head, "applied")
        wait_for(lambda: (watch.launch("tb3-04") or {}).get("revision") == head, "tb3-04 renamed")
        assert watch.launch("tb3-02") == before
    finally:
        running.stop()


def test_a_reconciler_started_on_a_bad_commit_serves_the_last_good_one(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url)
    good = lab.head()
    wait_for(lambda: published(watch, lab, good), "the lab published")
    running.stop()

    lab.write("configs/fleet.yaml", "robots: [not, a, mapping]\n")
    bad = lab.commit("broken")
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url)
    try:
        status = watch.wait_reconciler(lambda s: s.last_attempted_revision == bad, "attempted")
        assert status.last_applied_revision == good and not status.ready
        # The broker forgets everything: the last good revision (learned from the retained
        # status, not from a file) is published again, the bad one still is not.
        mosquitto.stop()
        mosquitto.start()
        wait_for(lambda: published(watch, lab, good), "the last good revision refilled")
        # A broker that shuts down publishes the Last Wills of its clients: Offline for a
        # moment, Progressing while it refills, then Stalled again.
        status = watch.wait_reconciler(
            lambda s: s.last_attempted_revision == bad and s.state == "Stalled", "reported"
        )
        assert status.last_applied_revision == good and status.reason == "BuildFailed"
        assert status.failed_revision == bad
    finally:
        running.stop()


def test_remote_repository_is_polled(lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch) -> None:
    cache = lab.root.parent / "cache"
    running = Running(RemoteBranch(f"file://{lab.root}", "main", cache), mosquitto.url, 0.5)
    try:
        wait_for(lambda: published(watch, lab, lab.head()), "the remote head published")
        lab.replace("configs/fleet.yaml", "Guide bot", "Guide")
        head = lab.commit("rename")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == head, "fetched")
        assert published(watch, lab, head)
        status = watch.reconciler()
        assert status is not None and status.source == f"file://{lab.root}"

        # The remote goes away: the fleet stays as it is and the status says why.
        hidden = lab.root.with_name("hidden")
        lab.root.rename(hidden)
        try:
            status = watch.wait_reconciler(lambda s: not s.ready, "the fetch failure reported")
            assert status.state == "Stalled" and status.last_applied_revision == head
            assert any("fetching" in d for d in map(str, status.diagnostics))
        finally:
            hidden.rename(lab.root)
        watch.wait_reconciler(lambda s: s.ready, "ready again once the remote is back")
        assert published(watch, lab, head)
    finally:
        running.stop()


def test_broker_down_at_start_is_waited_for(lab: GitLab, tmp_path: Path) -> None:
    broker = Mosquitto(tmp_path / "late-broker")
    broker.start()
    broker.stop()  # a known free port with nothing listening yet
    running = Running(LocalBranch(lab.root, "main"), broker.url)
    try:
        broker.start()
        watch = FleetWatch(broker.url)
        try:
            watch.wait_reconciler(lambda s: s.ready, "ready once the broker is up")
            assert published(watch, lab, lab.head())
        finally:
            watch.close()
    finally:
        running.stop()
        broker.kill()


def test_a_snapshot_larger_than_the_broker_queue_is_complete(mosquitto: Mosquitto) -> None:
    # Mosquitto drops queued QoS 1 messages past 1,000 per client (and with them the marker):
    # a big fleet's retained launch topics must still all arrive, and the snapshot complete.
    topics = [f"robotconf/robots/r{i:04d}/launch" for i in range(1500)]
    publisher = RetainedView(Connection(mosquitto.url), [], "robotconf/sync", role="test-pub")
    publisher.start()
    try:
        assert publisher.wait_synced(30)
        assert publisher.publish_retained([(t, b'{"digest": "x"}') for t in topics], 60)
    finally:
        publisher.stop()
    view = RetainedView(
        Connection(mosquitto.url), ["robotconf/robots/+/launch"], "robotconf/sync", role="test"
    )
    view.start()
    try:
        assert view.wait_synced(60)
        assert sorted(view.snapshot()) == topics
    finally:
        view.stop()
