"""The decide step, pure: what a reconcile step publishes and reports, without a broker or git."""

from __future__ import annotations

import pytest

from robotconf.configurator.render import render_fleet
from robotconf.contract.launch import StopRequest
from robotconf.contract.wire import AgentState, AgentStatus, StatusDiagnostic, Topics
from robotconf.readmodel.observed import parse_retained
from robotconf.reconciler.decide import Observation, Reason, decide
from robotconf.reconciler.desired import Desired, build_failure
from robotconf.reconciler.report import Followed, offline_status, status_of
from tests.support.lab import Lab

ROBOTS = ["tb3-01", "tb3-02", "tb3-03", "tb3-04", "tb3-05", "tb3-07"]
HEAD, GOOD = "h" * 40, "g" * 40


def desired(lab: Lab, revision: str) -> Desired:
    checked = lab.check()
    assert checked.ok, checked.errors
    return Desired(revision, render_fleet(checked.repo))


def test_a_valid_head_publishes_what_differs_and_is_applied(lab: Lab) -> None:
    build = desired(lab, HEAD)
    assert build.fleet is not None
    held = {"tb3-01": build.fleet.requests["tb3-01"].digest, "gone": "sha256:x"}
    decision = decide(Observation(head=HEAD, build=build, launches=held))
    assert decision.target is build and decision.actions is not None
    assert sorted(decision.actions.publish) == [r for r in ROBOTS if r != "tb3-01"]
    assert decision.actions.clear == ["gone"]
    assert decision.condition.reason is Reason.APPLIED and decision.condition.state == "Ready"
    assert decision.progressing().state == "Progressing"


def test_an_invalid_head_keeps_the_last_good_revision_serving_and_refilled(lab: Lab) -> None:
    serving = desired(lab, GOOD)
    problem = StatusDiagnostic(
        path="configs/fleet.yaml", line=3, column=5, code="RC501", message="x"
    )
    broken = Desired(HEAD, None, [problem], omitted=7)
    decision = decide(Observation(head=HEAD, build=broken, serving=serving, launches={}))
    assert decision.target is serving and decision.actions is not None
    assert sorted(decision.actions.publish) == ROBOTS  # the broker lost them: refilled
    condition = decision.condition
    assert condition.reason is Reason.BUILD_FAILED and condition.state == "Stalled"
    assert condition.failed_revision == HEAD and condition.diagnostics == (problem,)
    assert condition.more_diagnostics == 7
    assert f"serving {GOOD[:12]}" in condition.message


def test_an_empty_fleet_is_refused_and_nothing_is_cleared(lab: Lab) -> None:
    serving = desired(lab, GOOD)
    assert serving.fleet is not None
    lab.write("configs/fleet.yaml", "robots: {}\n")
    empty = desired(lab, HEAD)
    held = {r: serving.fleet.requests[r].digest for r in ROBOTS}
    decision = decide(Observation(head=HEAD, build=empty, serving=serving, launches=held))
    assert decision.target is serving and not decision.changes
    assert decision.condition.reason is Reason.EMPTY_FLEET_REFUSED
    (problem,) = decision.condition.diagnostics
    assert problem.path == "configs/fleet.yaml" and "allow_empty" in problem.message


@pytest.mark.parametrize(
    ("head", "crashed", "reason"),
    [(None, False, Reason.SOURCE_UNAVAILABLE), (HEAD, True, Reason.INTERNAL_ERROR)],
)
def test_why_a_head_is_not_applied(head: str | None, crashed: bool, reason: Reason) -> None:
    seen = Observation(head=head, build=build_failure(HEAD, "boom"), build_crashed=crashed)
    decision = decide(seen)
    assert decision.target is None and decision.actions is None
    assert decision.condition.reason is reason and decision.condition.state == "Stalled"


def test_a_failed_fetch_is_stale_not_ready(lab: Lab) -> None:
    build = desired(lab, HEAD)
    decision = decide(Observation(head=HEAD, build=build, fetch_error="cannot fetch"))
    condition = decision.condition
    assert condition.reason is Reason.SOURCE_UNAVAILABLE and condition.failed_revision is None
    assert [d.message for d in condition.diagnostics] == ["cannot fetch"]


def test_a_robot_still_running_after_it_left_the_fleet_is_cleared_again(lab: Lab) -> None:
    build = desired(lab, HEAD)
    assert build.fleet is not None
    held = {r: build.fleet.requests[r].digest for r in ROBOTS}
    decision = decide(Observation(head=HEAD, build=build, launches=held, active={"old"}))
    assert decision.actions is not None and decision.actions.clear == ["old"]


def test_the_retained_topics_read_into_what_the_broker_holds() -> None:
    topics = Topics()
    stop = StopRequest(robot_id="r2", revision=GOOD)
    running = AgentStatus(robot_id="r4", state=AgentState.RUNNING)
    retained = parse_retained(
        {
            topics.launch("r1"): b'{"digest": "sha256:1"}',
            topics.launch("r2"): stop.payload(),  # a stop: nothing assigned
            topics.launch("r3"): StopRequest(robot_id="r1", revision=GOOD).payload(),
            topics.launch("r5"): b"[not an object",
            topics.status("r4"): running.model_dump_json().encode(),
        },
        topics,
        requests=False,
    )
    # Another robot's stop, or garbage, is held but unreadable: replaced or cleared.
    assert retained.launch_digests() == {"r1": "sha256:1", "r3": None, "r5": None}
    assert retained.active() == {"r4"}
    assert retained.ignored == {"launch": 2}


def test_a_quiet_resync_keeps_the_counts_of_the_apply_that_changed_something(lab: Lab) -> None:
    serving = desired(lab, HEAD)
    followed = Followed("main", "/lab", 30.0)
    applied = decide(Observation(head=HEAD, build=serving, launches={}))
    first = status_of(
        applied.condition,
        applied.actions,
        serving=serving,
        head=HEAD,
        previous=None,
        followed=followed,
    )
    assert (first.state, first.published, first.robots) == ("Ready", 6, 6)
    quiet = decide(Observation(head=None, build=build_failure("", "gone"), serving=serving))
    later = status_of(
        quiet.condition, None, serving=serving, head=None, previous=first, followed=followed
    )
    assert later.published == 6 and later.last_attempted_revision == HEAD
    assert later.state == "Stalled" and later.reason == "SourceUnavailable"
    assert offline_status(later, "bye").last_applied_revision == HEAD
