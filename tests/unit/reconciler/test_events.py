"""Alert events, pure: transitions only, once each; receiver URLs, bodies and metric addresses."""

from __future__ import annotations

import json

import pytest

from robotconf.contract.lifecycle import parse_address
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    CommitLine,
    ReconcilerStatus,
    RolloutStatus,
)
from robotconf.readmodel.events import REMEMBERED, Event, Kind, Seen, Told, resumed, transitions
from robotconf.readmodel.verdicts import DesiredRobot, Verdict
from robotconf.reconciler.notify import parse_receiver
from robotconf.reconciler.telemetry import verdict_counts

D1 = "sha256:" + "1" * 64
D2 = "sha256:" + "2" * 64
GOOD, BAD, WORSE = "a" * 40, "b" * 40, "c" * 40


def stalled(revision: str, reason: str = "BuildFailed") -> ReconcilerStatus:
    return ReconcilerStatus(
        state="Stalled",
        ready=False,
        reason=reason,
        branch="main",
        last_applied_revision=GOOD,
        failed_revision=revision,
        message="configs/fleet.yaml: error RC101 nope",
    )


def ready() -> ReconcilerStatus:
    return ReconcilerStatus(
        state="Ready", ready=True, reason="Applied", branch="main", last_applied_revision=GOOD
    )


def robot(state: AgentState, digest: str | None = D1, message: str = "") -> AgentStatus:
    return AgentStatus(robot_id="r1", state=state, digest=digest, revision=GOOD, message=message)


def run(seens: list[Seen]) -> list[list[Event]]:
    """The events of each observation in turn, the memory carried along."""
    told, out = Told(), []
    for seen in seens:
        told, events = transitions(told, seen, 1.0)
        out.append(events)
    return out


def kinds(events: list[list[Event]]) -> list[list[Kind]]:
    return [[e.kind for e in step] for step in events]


def test_a_refused_commit_is_told_once_per_revision_whatever_comes_between() -> None:
    steps = run(
        [
            Seen(ready()),
            Seen(stalled(BAD)),
            Seen(stalled(BAD)),  # a resync
            Seen(stalled(BAD, "BrokerUnavailable")),  # something else stalls it a while
            Seen(stalled(BAD)),
            Seen(stalled(WORSE, "EmptyFleetRefused")),
            Seen(stalled(WORSE, "EmptyFleetRefused")),
        ]
    )
    assert kinds(steps) == [[], [Kind.COMMIT_REFUSED], [], [], [], [Kind.COMMIT_REFUSED], []]
    first, second = steps[1][0], steps[5][0]
    assert (first.revision, first.reason, first.branch) == (BAD, "BuildFailed", "main")
    assert (second.revision, second.reason) == (WORSE, "EmptyFleetRefused")
    assert "RC101" in first.message and BAD[:12] in first.message


FIX = "f" * 40


def applying(revision: str, state: str = "Ready", reason: str = "Applied") -> ReconcilerStatus:
    """The head `revision` accepted: applied (Ready), or being rolled out (Progressing)."""
    return ReconcilerStatus(
        state=state,  # type: ignore[arg-type]
        ready=state == "Ready",
        reason=reason,
        branch="main",
        last_applied_revision=revision,
        last_attempted_revision=revision,
    )


def refused(revision: str, reason: str = "BuildFailed") -> ReconcilerStatus:
    return stalled(revision, reason).model_copy(update={"last_attempted_revision": revision})


def test_a_refused_branch_applying_again_is_told_once() -> None:
    steps = run(
        [
            Seen(applying(GOOD)),
            Seen(refused(BAD)),
            Seen(refused(BAD)),  # a resync
            Seen(applying(FIX)),
            Seen(applying(FIX)),  # resyncs: heartbeats
            Seen(applying(FIX)),
        ]
    )
    assert kinds(steps) == [[], [Kind.COMMIT_REFUSED], [], [Kind.COMMIT_RECOVERED], [], []]
    recovered = steps[3][0]
    assert (recovered.revision, recovered.refused_revision) == (FIX, BAD)
    assert (recovered.branch, recovered.reason) == ("main", "Applied")
    assert FIX[:12] in recovered.message and BAD[:12] in recovered.message
    assert recovered.as_json()["refused_revision"] == BAD


def test_recovery_waits_for_the_head_to_be_accepted() -> None:
    """Another stall after a refusal is no recovery; a rollout of a later head is (the branch
    applies again); a second refusal before it is the one the recovery names."""
    steps = run(
        [
            Seen(refused(BAD)),
            Seen(stalled(BAD, "BrokerUnavailable")),
            Seen(stalled(FIX, "SourceUnavailable")),
            # a rollout already under way, the refused head still the head: not recovered
            Seen(applying(GOOD, "Progressing", "Progressing").model_copy(
                update={"last_attempted_revision": BAD})),
            Seen(refused(WORSE, "EmptyFleetRefused")),
            Seen(applying(FIX, "Progressing", "Progressing")),
            Seen(applying(FIX)),
        ]
    )  # fmt: skip
    assert kinds(steps) == [
        [Kind.COMMIT_REFUSED],
        [],
        [],
        [],
        [Kind.COMMIT_REFUSED],
        [Kind.COMMIT_RECOVERED],
        [],
    ]
    assert steps[5][0].refused_revision == WORSE and steps[5][0].reason == "Progressing"


def test_nothing_recovers_when_nothing_was_refused() -> None:
    """At start-up, or after stalls that are not refusals."""
    assert kinds(run([Seen(applying(GOOD)), Seen(applying(FIX))])) == [[], []]
    steps = run([Seen(stalled(BAD, "SourceUnavailable")), Seen(applying(FIX))])
    assert kinds(steps) == [[], []]


def test_a_restarted_reconciler_resumes_a_refusal_found_on_the_broker() -> None:
    """Found stalled on a refusal (the one before died before its Last Will said Offline): the
    refusal is not told again, and the recovery is."""
    told = resumed(Told(), refused(BAD))
    told, events = transitions(told, Seen(refused(BAD)), 1.0)
    assert events == []
    told, events = transitions(told, Seen(applying(FIX)), 2.0)
    assert [(e.kind, e.revision, e.refused_revision) for e in events] == [
        (Kind.COMMIT_RECOVERED, FIX, BAD)
    ]
    # Found offline, ready, stalled otherwise, or nothing: nothing to resume.
    offline = refused(BAD).model_copy(update={"state": "Offline", "reason": "Offline"})
    for found in (None, applying(GOOD), stalled(BAD, "BrokerUnavailable"), offline):
        assert resumed(Told(), found) == Told()


def test_other_stalls_are_not_refusals() -> None:
    steps = run([Seen(stalled(BAD, "SourceUnavailable")), Seen(stalled(BAD, "InternalError"))])
    assert kinds(steps) == [[], []]


def test_the_memory_of_refused_revisions_is_bounded() -> None:
    told = Told()
    for n in range(REMEMBERED + 10):
        told, _ = transitions(told, Seen(stalled(f"{n:040x}")), 1.0)
    assert len(told.refused) == REMEMBERED and told.refused[-1] == f"{REMEMBERED + 9:040x}"


def with_rollout(state: str, revision: str = BAD) -> ReconcilerStatus:
    status = ready()
    rollout = RolloutStatus(revision=revision, state=state, message="2 of 2 failed")  # type: ignore[arg-type]
    return status.model_copy(update={"rollout": rollout})


def test_a_halted_or_rolled_back_rollout_is_told_once_per_revision() -> None:
    steps = run(
        [
            Seen(with_rollout("Progressing")),
            Seen(with_rollout("Halted")),
            Seen(with_rollout("Halted")),
            Seen(with_rollout("Progressing", WORSE)),
            Seen(with_rollout("RolledBack", WORSE)),
            Seen(with_rollout("RolledBack", WORSE)),
            Seen(with_rollout("Complete", GOOD)),
        ]
    )
    assert kinds(steps) == [
        [],
        [Kind.ROLLOUT_HALTED],
        [],
        [],
        [Kind.ROLLOUT_ROLLED_BACK],
        [],
        [],
    ]
    assert steps[1][0].revision == BAD and "halted" in steps[1][0].message


def robots(status: AgentStatus | None, digest: str = D1, since: float = -100.0) -> Seen:
    """r1 as `status` says, running (if it runs) since `since`: settled at time 1.0."""
    return Seen(ready(), {"r1": status} if status else {}, {"r1": digest}, {"r1": since})


@pytest.mark.parametrize("state", [AgentState.FAILED, AgentState.BACKOFF, AgentState.REJECTED])
def test_a_robot_degrading_is_told_once_then_once_back_in_sync(state: AgentState) -> None:
    steps = run(
        [
            robots(robot(AgentState.RUNNING)),
            robots(robot(state, message="exit 3")),
            robots(robot(state, message="exit 3")),
            robots(robot(AgentState.STARTING)),
            robots(robot(AgentState.BACKOFF)),  # still degraded: not told again
            robots(robot(AgentState.RUNNING)),
            robots(robot(AgentState.RUNNING)),
        ]
    )
    assert kinds(steps) == [
        [],
        [Kind.ROBOT_DEGRADED],
        [],
        [],
        [],
        [Kind.ROBOT_IN_SYNC],
        [],
    ]
    told = steps[1][0]
    assert (told.robot, told.reason) == ("r1", state.value) and "exit 3" in told.message


def test_offline_then_degraded_are_two_transitions() -> None:
    steps = run(
        [
            robots(robot(AgentState.OFFLINE)),
            robots(robot(AgentState.FAILED)),
            robots(robot(AgentState.OFFLINE)),
        ]
    )
    assert kinds(steps) == [[Kind.ROBOT_OFFLINE], [Kind.ROBOT_DEGRADED], [Kind.ROBOT_OFFLINE]]


def test_a_robot_is_in_sync_only_on_the_desired_digest_and_only_after_an_alert() -> None:
    steps = run(
        [
            robots(robot(AgentState.RUNNING, D2)),  # an older request: on its way
            robots(robot(AgentState.RUNNING, D1)),  # a normal rollout: nothing to tell
            robots(robot(AgentState.FAILED, D1)),
            robots(robot(AgentState.RUNNING, D2)),  # running, but not what it should
            robots(robot(AgentState.RUNNING, D1)),
        ]
    )
    assert kinds(steps) == [[], [], [Kind.ROBOT_DEGRADED], [], [Kind.ROBOT_IN_SYNC]]


def test_back_in_sync_only_once_settled() -> None:
    told, events = transitions(Told(), robots(robot(AgentState.BACKOFF)), 100.0)
    assert [e.kind for e in events] == [Kind.ROBOT_DEGRADED]
    # Running again since 98 (a crash loop runs a moment before each crash): not yet settled.
    told, events = transitions(told, robots(robot(AgentState.RUNNING), since=98.0), 100.0)
    assert events == [] and told.alerting == {"r1": Kind.ROBOT_DEGRADED}
    told, events = transitions(told, robots(robot(AgentState.BACKOFF)), 101.0)
    assert events == []  # still the same degradation
    told, events = transitions(told, robots(robot(AgentState.RUNNING), since=101.0), 105.9)
    assert events == []
    told, events = transitions(told, robots(robot(AgentState.RUNNING), since=101.0), 106.0)
    assert [e.kind for e in events] == [Kind.ROBOT_IN_SYNC] and not told.alerting


def test_unassigned_robots_and_unknown_statuses_tell_nothing() -> None:
    failed = robot(AgentState.FAILED)
    steps = run(
        [
            Seen(ready(), {"r1": failed}, {}),  # not assigned
            Seen(ready(), None, {"r1": D1}),  # statuses not known yet
            robots(None),  # never reported
        ]
    )
    assert kinds(steps) == [[], [], []]
    # Unassigned while alerting: forgotten, so a later assignment that fails is told again.
    told, _ = transitions(Told(), robots(failed), 1.0)
    told, events = transitions(told, Seen(ready(), {"r1": failed}, {}), 1.0)
    assert not events and not told.alerting
    assert [e.kind for e in transitions(told, robots(failed), 1.0)[1]] == [Kind.ROBOT_DEGRADED]


def test_receivers_get_the_event_json_or_slack_text() -> None:
    event = Event(Kind.COMMIT_REFUSED, "bbbb on main refused", 2.5, "main", BAD, None, "X")
    plain = parse_receiver("http://127.0.0.1:9/hook")
    slack = parse_receiver("slack:https://hooks.example/services/T/B/SECRET", 2)
    assert json.loads(plain.body(event)) == {
        "event": "commit_refused",
        "at": 2.5,
        "branch": "main",
        "revision": BAD,
        "robot": None,
        "reason": "X",
        "message": "bbbb on main refused",
        "refused_revision": None,
        "subject": None,
    }
    assert json.loads(slack.body(event)) == {
        "text": "robotconf commit refused: bbbb on main refused"
    }
    # The commit's subject, when the reconciler's status describes the commit.
    status = ReconcilerStatus(
        state="Stalled",
        ready=False,
        reason="BuildFailed",
        branch="main",
        failed_revision=BAD,
        commits=[CommitLine(revision=BAD, subject="Break <!channel> fleet.yaml")],
    )
    told = transitions(Told(), Seen(status), 3.0)[1]
    assert [e.subject for e in told] == ["Break <!channel> fleet.yaml"]
    assert json.loads(plain.body(told[0]))["subject"] == "Break <!channel> fleet.yaml"
    assert "<!channel>" not in json.loads(slack.body(told[0]))["text"]  # inert in a chat
    assert slack.slack and not plain.slack
    assert slack.name == "#2 slack:https://hooks.example"


@pytest.mark.parametrize(
    "url",
    [
        "ftp://host/x",
        "hooks.example/x",
        "slack:mqtt://host",
        "http:///nohost",
        "http://user:hunter2@host:99999/x",
        "http://user:pa%ss:hunter2@host:99999x/",  # the password makes the port unparsable
        "http://user:hunter2/x@host/",  # an unencoded / makes `user` the host, `hunter2` a port
        "http://user:hunter2#x@host/",
        "http://user:hunter2@[::1/",
        "http://user:hunter2@host/a b",
        "http://user:hunter2@host/\x1b[2J",
        "http://user:hunter2@h\u00f6st/",
        "slack:ftp://user:hunter2@host/x",
    ],
)
def test_bad_receiver_urls_are_refused_without_their_secrets(url: str) -> None:
    with pytest.raises(ValueError) as caught:
        parse_receiver(url)
    assert "--notify #1" in str(caught.value) and "hunter2" not in str(caught.value)


def test_a_receiver_name_hides_credentials_and_path() -> None:
    receiver = parse_receiver("https://user:hunter2@alerts.example:8443/token/XYZ")
    assert receiver.name == "#1 https://alerts.example:8443"
    assert "hunter2" not in repr(receiver) and "XYZ" not in repr(receiver)
    assert receiver.url == "https://alerts.example:8443/token/XYZ"  # credentials: a header
    assert parse_receiver("http://[::1]:9/x", 3).name == "#3 http://[::1]:9"


def test_a_robot_message_is_data_in_json_and_inert_text_in_slack() -> None:
    forged = "\nERROR forged line\r\x1b[2J<!channel> & @here"
    told = run([robots(robot(AgentState.FAILED, message=forged))])[0][0]
    plain, slack = parse_receiver("http://h/x"), parse_receiver("slack:http://h/x")
    assert json.loads(plain.body(told))["message"] == f"r1 is failed: {forged}"
    text = json.loads(slack.body(told))["text"]
    assert text == (
        "robotconf robot degraded: r1 is failed: \\nERROR forged line\\r\\x1b[2J"
        "&lt;!channel&gt; &amp; @\u2060here"
    )


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:9108", ("127.0.0.1", 9108)),
        (":9108", ("0.0.0.0", 9108)),
        ("[::1]:9108", ("::1", 9108)),
        ("localhost:1", ("localhost", 1)),
    ],
)
def test_metrics_addresses(text: str, expected: tuple[str, int]) -> None:
    assert parse_address(text, "--metrics", "127.0.0.1:9108") == expected


@pytest.mark.parametrize(
    "text", ["9108", "host:", "host:http", "host:0", "host:70000", "", "host:\u00b2"]
)
def test_bad_metrics_addresses(text: str) -> None:
    with pytest.raises(ValueError, match=r"^--webhook .* must be HOST:PORT, e\.g\. :9292$"):
        parse_address(text, "--webhook", ":9292")


def test_verdict_counts_judge_robots_from_their_statuses() -> None:
    desired = {
        "r1": DesiredRobot("r1", "s", D1),
        "r2": DesiredRobot("r2", "s", D1),
        "r3": DesiredRobot("r3", "s", D1, suspended=True),
        "r4": DesiredRobot("r4", "s", D1),
    }
    statuses = {
        "r1": robot(AgentState.RUNNING, D1),
        "r2": robot(AgentState.FAILED, D1),
        "r3": robot(AgentState.RUNNING, D2),
        "r9": robot(AgentState.IDLE, None),
    }
    assert verdict_counts(desired, statuses) == {
        Verdict.IN_SYNC: 1,
        Verdict.DEGRADED: 1,
        Verdict.SUSPENDED: 1,
        Verdict.OFFLINE: 1,  # r4 never reported
        Verdict.UNASSIGNED: 1,
    }
    # A read the broker is known to have cut short: r4's status may have been dropped.
    lost = verdict_counts(desired, statuses, lost=True)
    assert lost[Verdict.UNKNOWN] == 1 and Verdict.OFFLINE not in lost


def test_a_robot_is_told_once_into_drift_and_once_out_of_it() -> None:
    from robotconf.configurator.drift import UNKNOWN, Drift, DriftItem, Need

    need = Need("scan", "/scan", "topic", "sensor_msgs/msg/LaserScan", ("patrol_with_lidar",))
    lacking = Drift("reported", (DriftItem("r1", need),))
    fits, failed = Drift("reported"), Drift("error", note="ros2 timed out")
    desired = {"r1": D1}
    steps = run(
        [
            Seen(ready(), {}, desired, drift=None),  # interfaces not known yet: nothing
            Seen(ready(), {}, desired, drift={"r1": fits}),
            Seen(ready(), {}, desired, drift={"r1": lacking}),
            Seen(ready(), {}, desired, drift={"r1": lacking}),  # a resync
            Seen(ready(), {}, desired, drift={"r1": UNKNOWN}),  # stopped reporting: no claim
            Seen(ready(), {}, desired, drift={"r1": failed}),
            Seen(ready(), {}, desired, drift={"r1": lacking}),  # still the same drift
            Seen(ready(), {}, desired, drift={"r1": fits}),
            Seen(ready(), {}, desired, drift={"r1": fits}),
            Seen(ready(), {}, {}, drift={"r1": lacking}),  # no longer assigned: not judged
        ]
    )
    assert kinds(steps) == [
        [],
        [],
        [Kind.ROBOT_DRIFTED],
        [],
        [],
        [],
        [],
        [Kind.ROBOT_DRIFT_CLEARED],
        [],
        [],
    ]
    drifted = steps[2][0]
    assert drifted.robot == "r1" and drifted.as_json()["event"] == "robot_drifted"
    assert drifted.message == (
        "r1 drifted: lacks /scan (sensor_msgs/msg/LaserScan), needed by patrol_with_lidar via "
        "mapping scan"
    )


def test_a_robot_deferring_is_told_once_per_deferral_assigned_or_leaving() -> None:
    held = robot(AgentState.DEFERRED, message="restart for request sha256:2 deferred by ...")
    leaving = Seen(ready(), {"r1": robot(AgentState.DEFERRED)}, {})  # its stop waits
    steps = run(
        [
            robots(robot(AgentState.RUNNING)),
            robots(held),
            robots(held),  # a resync
            robots(robot(AgentState.RUNNING, D2)),
            robots(held),  # another deferral
            leaving,
        ]
    )
    assert kinds(steps) == [[], [Kind.ROBOT_DEFERRED], [], [], [Kind.ROBOT_DEFERRED], []]
    told = steps[1][0]
    assert (told.robot, told.reason, told.revision) == ("r1", "deferred", GOOD)
    assert told.message == "r1 is deferred: restart for request sha256:2 deferred by ..."
    assert kinds(run([leaving])) == [[Kind.ROBOT_DEFERRED]]
