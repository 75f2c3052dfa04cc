"""Nothing a commit, a robot or a stranger sends takes the reconciler down, and its status
does not lie (issue 10): real Mosquitto, real git, real `robotconf` processes."""

from __future__ import annotations

import json
import logging
import re
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from robotconf.contract.launch import LaunchRequest, StopRequest
from robotconf.contract.mqtt import Connection
from robotconf.contract.signing import Signed, generate_keys, load_public_key, verify
from robotconf.contract.wire import ReconcilerStatus, Topics
from robotconf.readmodel.retained import Ignored, RetainedView
from robotconf.reconciler.builds import MAX_REQUEST_BYTES
from robotconf.reconciler.delivery import Signer
from robotconf.reconciler.desired import Desired, load_desired
from robotconf.reconciler.signer import make_signer
from robotconf.reconciler.source import LocalBranch
from tests.support.fleet import ROBOTS, GitLab, Running, robotconf_argv, start_reconciler
from tests.support.lab import ROOT as LAB
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

TOPICS = Topics()
DEEP = b"[" * 100_000 + b"]" * 100_000
BIG = b'{"digest": "' + b"x" * 2_000_000 + b'"}'  # over the 1 MiB bound, and Mosquitto's none
NOT_UTF8 = b'{"robot_id": "tb3-01", "state": "running\xff"}'
DUPLICATE = b'{"robot_id": "tb3-01", "state": "running", "state": "idle"}'
FAKE_PLACEHOLDER = b"\x00oversized x"  # what the reconciler keeps for a dropped payload, nearly
HOSTILE = [DEEP, BIG, NOT_UTF8, DUPLICATE, FAKE_PLACEHOLDER]


def publish(url: str, items: list[tuple[str, bytes]]) -> None:
    """Retained QoS 1, as any client of the broker may (no ACL in these tests)."""
    publisher = RetainedView(Connection(url), [], "robotconf/sync", role="test-evil")
    publisher.start()
    try:
        assert publisher.wait_synced(30)
        assert publisher.publish_retained(items, 60)
    finally:
        publisher.stop()


def serves(watch: FleetWatch, lab: GitLab, revision: str) -> bool:
    """The launch topics hold exactly the requests of `revision` (garbage tolerated)."""
    requests = lab.requests(revision)
    robots = set(requests) | set(ROBOTS)
    return all(watch.digest(r) == (requests[r].digest if r in requests else None) for r in robots)


def attempted(revision: str) -> Callable[[ReconcilerStatus], bool]:
    return lambda status: status.last_attempted_revision == revision


def status_cli(url: str, lab: GitLab, *extra: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("status", "--repo", str(lab.root), "--broker", url, *extra),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stderr + done.stdout, done.stderr
    return done


# ------------------------------------------------------------------ killed by data


def test_a_build_that_raises_is_stalled_and_the_next_good_commit_applied(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    good = lab.head()
    # While set, every revision but the first chokes the build. It is set before the bad
    # commit is made and cleared before the good one: the reconciler may build a commit
    # before `commit` has returned its id, so a set of ids filled after would race it.
    choking = threading.Event()
    calls: list[str] = []

    def builder(root: Path, revision: str) -> Desired:
        calls.append(revision)
        if choking.is_set() and revision != good:
            raise RecursionError("maximum recursion depth exceeded (an injected fault)")
        return load_desired(root, revision)

    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, 300.0, builder=builder)
    try:
        wait_for(lambda: serves(watch, lab, good), "the lab published")
        lab.replace("configs/fleet.yaml", "Guide bot", "Guide")
        choking.set()
        failed = lab.commit("a commit the build chokes on")
        # Its build is said first (Progressing), then its end: a loaded machine shows both.
        status = watch.wait_reconciler(
            lambda s: s.last_attempted_revision == failed and s.state != "Progressing", "tried"
        )
        assert status.state == "Stalled" and status.reason == "InternalError"
        assert status.failed_revision == failed and status.last_applied_revision == good
        assert any("RecursionError" in d for d in map(str, status.diagnostics))
        assert serves(watch, lab, good)
        assert running.thread.is_alive()

        lab.replace("configs/fleet.yaml", "Guide", "Guide robot")
        choking.clear()
        fixed = lab.commit("the next good commit")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == fixed, "applied")
        assert serves(watch, lab, fixed)
        assert calls.count(failed) == 1  # built once, not at every wake: no busy loop
    finally:
        running.stop()


def test_an_exception_while_applying_is_reported_and_retried(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Path
) -> None:
    keys = generate_keys(tmp_path / "keys")
    signer = make_signer(keys.private)
    assert signer is not None
    sign: Signer = signer
    failures = [RuntimeError("injected: the signer failed"), ValueError("injected again")]

    def flaky(request: Signed) -> Signed:
        if failures:
            raise failures.pop(0)
        return sign(request)

    seen: list[ReconcilerStatus] = []
    running = Running(
        LocalBranch(lab.root, "main"), mosquitto.url, signer=flaky, on_reconciled=seen.append
    )
    try:
        head = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == head, "applied")
        assert serves(watch, lab, head)
        internal = [s for s in seen if s.reason == "InternalError"]
        assert len(internal) == 2 and all(s.state == "Stalled" for s in internal)
        assert "injected: the signer failed" in internal[0].message
        assert running.thread.is_alive()
    finally:
        running.stop()


def test_a_request_too_large_for_an_agent_is_a_build_error(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    def builder(root: Path, revision: str) -> Desired:
        desired = load_desired(root, revision)
        if revision != lab.first and desired.fleet is not None:
            request = desired.fleet.requests["tb3-03"]
            # Rendered as any request is: its digest covers the long name.
            desired.fleet.requests["tb3-03"] = request.scenario_requests.request(
                "tb3-03", "x" * MAX_REQUEST_BYTES, request.revision, request.namespace
            )
        return desired

    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, builder=builder)
    try:
        wait_for(lambda: serves(watch, lab, lab.first), "the lab published")
        big = lab.commit("a request over the size agents accept")
        status = watch.wait_reconciler(lambda s: s.last_attempted_revision == big, "tried")
        assert status.state == "Stalled" and status.reason == "BuildFailed"
        assert status.last_applied_revision == lab.first
        assert any("tb3-03" in d and "bytes, over the" in d for d in map(str, status.diagnostics))
    finally:
        running.stop()


def test_hostile_payloads_are_skipped_and_counted(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, 1.0)
    try:
        good = lab.head()
        wait_for(lambda: serves(watch, lab, good), "the lab published")
        items = [(TOPICS.status(f"evil-{i}"), p) for i, p in enumerate(HOSTILE)]
        items += [(TOPICS.launch(f"evil-{i}"), p) for i, p in enumerate(HOSTILE)]
        items += [(TOPICS.description(f"evil-{i}"), p) for i, p in enumerate(HOSTILE)]
        items += [(TOPICS.status("tb3-01"), DEEP), (TOPICS.launch("tb3-02"), BIG)]
        publish(mosquitto.url, items)
        publish(mosquitto.url, [(TOPICS.reconciler_status, DEEP)])

        # Garbage on launch topics is replaced (assigned) or cleared (not assigned), the
        # reconciler's own status is restored, and every unreadable payload is counted.
        wait_for(lambda: serves(watch, lab, good), "the launch topics repaired")
        wait_for(
            lambda: all(watch.digest(f"evil-{i}") is None for i in range(len(HOSTILE))), "cleared"
        )
        status = watch.wait_reconciler(
            lambda s: (
                s.ready
                and s.ignored_payloads.get("status", 0) >= 5
                and s.ignored_payloads.get("launch", 0) >= 5
                and s.ignored_payloads.get("reconciler-status", 0) >= 1
            ),
            "the ignored payloads counted",
        )
        assert status.last_applied_revision == good
        assert running.controller.view.oversized >= 1  # dropped on arrival, never held

        lab.replace("configs/fleet.yaml", "Guide bot", "Guide")
        head = lab.commit("the next commit")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == head, "applied")
        assert serves(watch, lab, head) and running.thread.is_alive()

        done = status_cli(mosquitto.url, lab)
        assert done.returncode == 1  # no agent runs: the robots are offline
        assert "unreadable retained payloads skipped" in done.stdout
        report = json.loads(status_cli(mosquitto.url, lab, "--json").stdout)
        assert report["ignored_payloads"]["status"] >= 5
        assert report["ignored_payloads"]["description"] >= 4
    finally:
        running.stop()


def test_a_failing_handler_does_not_end_the_connection(mosquitto: Mosquitto) -> None:
    calls: list[int] = []

    def explode() -> None:
        calls.append(1)
        raise RuntimeError("a handler bug")

    view = RetainedView(
        Connection(mosquitto.url),
        ["robotconf/robots/+/launch"],
        "robotconf/sync",
        on_change=explode,
    )
    view.start()
    try:
        assert view.wait_synced(30)
        publish(mosquitto.url, [(TOPICS.launch("a"), b"1")])
        wait_for(lambda: view.snapshot().get(TOPICS.launch("a")) == b"1", "the first message")
        publish(mosquitto.url, [(TOPICS.launch("b"), b"2")])
        wait_for(lambda: view.snapshot().get(TOPICS.launch("b")) == b"2", "the second message")
        assert len(calls) >= 2 and view.connected
    finally:
        view.stop()


# ------------------------------------------------------------------ the status does not lie


def test_a_reconciler_killed_by_nothing_but_sigkill_leaves_its_will(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Path
) -> None:
    proc = start_reconciler(lab, mosquitto.url, tmp_path / "reconciler.log", "--interval", "5")
    try:
        good = lab.head()
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == good, "ready")

        # Commits whose content crashed the build once: the process goes on, and says why.
        for text in ("robots: !!float abc\n", 'robots: {"tb3-01\\n": {scenario: guide-gazebo}}\n'):
            lab.write("configs/fleet.yaml", text)
            bad = lab.commit("bad data")
            status = watch.wait_reconciler(attempted(bad), "the bad commit tried")
            assert status.state == "Stalled" and status.failed_revision == bad
            assert status.reason in ("BuildFailed", "InternalError") and status.diagnostics
            assert status.last_applied_revision == good
            assert proc.alive()

        lab.write("configs/fleet.yaml", (LAB / "configs/fleet.yaml").read_text(encoding="utf-8"))
        lab.replace("configs/fleet.yaml", "Guide bot", "Guide")
        fixed = lab.commit("fixed")
        watch.wait_reconciler(lambda s: s.ready and s.last_applied_revision == fixed, "applied")
        done = status_cli(mosquitto.url, lab, "--json")
        assert json.loads(done.stdout)["reconciler_health"] == "ok"

        proc.kill()  # SIGKILL: no goodbye, only the broker's Last Will
        will = watch.wait_reconciler(lambda s: s.state == "Offline", "the Last Will")
        assert not will.ready and will.reason == "Offline"
        assert will.last_applied_revision == fixed  # the will was renewed with each apply

        done = status_cli(mosquitto.url, lab)
        assert done.returncode == 1
        assert "reconciler: Offline" in done.stdout
        report = json.loads(status_cli(mosquitto.url, lab, "--json").stdout)
        assert report["reconciler_health"] == "offline" and report["in_sync"] is False
    finally:
        proc.stop()


def test_a_stale_or_missing_reconciler_fails_status(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    done = status_cli(mosquitto.url, lab)
    assert done.returncode == 1 and "reconciler: MISSING" in done.stdout

    # A Ready status whose heartbeat stopped long ago: hung, or cut off without a will.
    hung = ReconcilerStatus(
        state="Ready", ready=True, reason="Applied", heartbeat=time.time() - 3600, interval=5
    )
    publish(mosquitto.url, [(TOPICS.reconciler_status, hung.model_dump_json().encode())])
    watch.wait_reconciler(lambda s: s.heartbeat == hung.heartbeat, "the hung status")
    done = status_cli(mosquitto.url, lab)
    # 3600 s when published; a loaded machine may take a second or two to run the CLI.
    assert done.returncode == 1
    assert re.search(r"STALE: its last heartbeat is 360[0-9] s old", done.stdout), done.stdout
    report = json.loads(status_cli(mosquitto.url, lab, "--json").stdout)
    assert report["reconciler_health"] == "stale"


def test_the_heartbeat_changes_nothing_else(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, 0.3)
    try:
        first = watch.wait_reconciler(lambda s: s.ready, "ready")
        assert first.interval == 0.3 and first.heartbeat is not None
        watch.live_launches.clear()
        beats: set[float] = set()

        def beating() -> bool:
            status = watch.reconciler()
            if status is not None and status.heartbeat is not None:
                beats.add(status.heartbeat)
            return len(beats) >= 4

        wait_for(beating, "a few heartbeats")
        last = watch.reconciler()
        assert last is not None
        assert last.since == first.since and last.published == first.published
        exclude = {"heartbeat"}
        assert last.model_dump(exclude=exclude) == first.model_dump(exclude=exclude)
        assert watch.live_launches == []  # nothing republished
    finally:
        running.stop()


def test_a_will_fired_while_the_reconciler_lives_is_replaced_at_once(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch
) -> None:
    """A will of one of its connections that dropped (or of a broker shutting down) must not
    leave a live reconciler shown offline until the next resync (here: minutes away)."""
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url, 300.0)
    try:
        ready = watch.wait_reconciler(lambda s: s.ready, "ready")
        will = ReconcilerStatus(state="Offline", ready=False, reason="Offline")
        publish(mosquitto.url, [(TOPICS.reconciler_status, will.model_dump_json().encode())])
        status = watch.wait_reconciler(lambda s: s.state == "Ready", "its status back")
        assert status.last_applied_revision == ready.last_applied_revision
    finally:
        running.stop()


def test_a_stopped_reconciler_says_so(lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch) -> None:
    running = Running(LocalBranch(lab.root, "main"), mosquitto.url)
    head = lab.head()
    watch.wait_reconciler(lambda s: s.ready, "ready")
    running.stop()
    status = watch.wait_reconciler(lambda s: s.state == "Offline", "offline")
    assert status.last_applied_revision == head and "stopped" in status.message


# ------------------------------------------------------------------ signed stops


def test_a_signing_reconciler_stops_a_removed_robot_with_a_signed_stop(
    lab: GitLab, mosquitto: Mosquitto, watch: FleetWatch, tmp_path: Path
) -> None:
    keys = generate_keys(tmp_path / "keys")
    running = Running(
        LocalBranch(lab.root, "main"), mosquitto.url, 0.3, signer=make_signer(keys.private)
    )
    try:
        wait_for(lambda: serves(watch, lab, lab.head()), "the lab published")
        lab.replace("configs/fleet.yaml", "  tb3-05:", "  # tb3-05:")
        removed = lab.commit("retire tb3-05")
        status = watch.wait_reconciler(lambda s: s.last_applied_revision == removed, "applied")
        assert status.cleared == 1
        payload = watch.retained()[TOPICS.launch("tb3-05")]
        stop = StopRequest.model_validate_json(payload)
        assert stop.robot_id == "tb3-05" and stop.revision == removed
        assert verify(stop, load_public_key(keys.public)) is None

        # Later passes leave the stop alone: nothing is published again.
        watch.live_launches.clear()
        heartbeat = status.heartbeat or 0.0
        watch.wait_reconciler(lambda s: (s.heartbeat or 0) > heartbeat + 1, "more passes")
        assert watch.live_launches == []
        report = json.loads(status_cli(mosquitto.url, lab, "--json").stdout)
        verdicts = {r["robot_id"]: r["verdict"] for r in report["robots"]}
        assert verdicts["tb3-05"] == "Unassigned"

        # Assigned again: it gets its (signed) request back.
        lab.replace("configs/fleet.yaml", "  # tb3-05:", "  tb3-05:")
        back = lab.commit("tb3-05 is back")
        wait_for(lambda: serves(watch, lab, back), "tb3-05 published again")
        request = LaunchRequest.model_validate_json(watch.retained()[TOPICS.launch("tb3-05")])
        assert verify(request, load_public_key(keys.public)) is None
    finally:
        running.stop()


def test_skipped_payloads_are_counted_once_and_logged_sparingly(
    caplog: pytest.LogCaptureFixture,
) -> None:
    ignored = Ignored(logging.getLogger("test.ignored"))
    with caplog.at_level(logging.WARNING, "test.ignored"):
        for _ in range(3):  # a resync reads the same retained garbage again: counted once
            ignored.note("status", "robotconf/robots/a/status", DEEP, "nested too deep")
        for i in range(50):  # a robot publishing garbage in a loop: one line a minute
            ignored.note("status", "robotconf/robots/b/status", b"%d" % i, "not an object")
    assert ignored.counts() == {"status": 51}
    assert len(caplog.records) == 1 and "nested too deep" in caplog.records[0].getMessage()
