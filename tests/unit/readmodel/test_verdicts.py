"""Fleet status verdicts and formatting, pure: no broker."""

from __future__ import annotations

import pytest

from robotconf.contract.launch import StopRequest
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    ReconcilerStatus,
    RobotDescription,
    Topics,
)
from robotconf.readmodel.observed import Retained, RobotSeen, parse_retained
from robotconf.readmodel.retained import oversized
from robotconf.readmodel.verdicts import (
    DesiredRobot,
    FleetStatus,
    Health,
    Verdict,
    build_rows,
    verdict,
)
from robotconf.workstation.cli.fleet_view import fleet_status_text

D1 = "sha256:" + "1" * 64
D2 = "sha256:" + "2" * 64


def want(digest: str = D1, suspended: bool = False) -> DesiredRobot:
    return DesiredRobot("r1", "delivery", digest, suspended)


def seen(
    state: AgentState | None, digest: str | None = D1, published: str | None = D1
) -> RobotSeen:
    status = None if state is None else AgentStatus(robot_id="r1", state=state, digest=digest)
    return RobotSeen(launch_digest=published, status=status)


def test_running_the_desired_request_is_in_sync() -> None:
    assert verdict(want(), seen(AgentState.RUNNING))[0] is Verdict.IN_SYNC


def test_offline_and_never_seen_robots_are_offline() -> None:
    assert verdict(want(), seen(AgentState.OFFLINE))[0] is Verdict.OFFLINE
    assert verdict(want(), seen(None))[0] is Verdict.OFFLINE


def test_failures_are_degraded() -> None:
    for state in (AgentState.FAILED, AgentState.REJECTED, AgentState.BACKOFF, AgentState.EXITED):
        assert verdict(want(), seen(state))[0] is Verdict.DEGRADED, state


def test_on_the_way_is_progressing() -> None:
    # Not published yet, an old digest still running, starting, idle.
    assert verdict(want(), seen(AgentState.RUNNING, published=D2))[0] is Verdict.PROGRESSING
    assert verdict(want(), seen(AgentState.RUNNING, digest=D2))[0] is Verdict.PROGRESSING
    assert verdict(want(), seen(AgentState.STARTING))[0] is Verdict.PROGRESSING
    assert verdict(want(), seen(AgentState.IDLE, digest=None))[0] is Verdict.PROGRESSING


def test_suspended_wins_over_anything_observed() -> None:
    assert verdict(want(suspended=True), seen(AgentState.FAILED))[0] is Verdict.SUSPENDED


def test_not_in_the_fleet_is_unassigned_once_its_brain_stopped() -> None:
    assert verdict(None, seen(AgentState.IDLE, digest=None, published=None))[0] is (
        Verdict.UNASSIGNED
    )
    assert verdict(None, seen(AgentState.RUNNING))[0] is Verdict.PROGRESSING


def test_rows_are_worst_first_and_warn_about_templates() -> None:
    desired = {
        "a-ok": DesiredRobot("a-ok", "s", D1, template="turtlebot3-camera"),
        "b-off": DesiredRobot("b-off", "s", D1),
        "c-bad": DesiredRobot("c-bad", "s", D1),
    }
    retained = Retained(
        robots={
            "a-ok": RobotSeen(
                launch_digest=D1,
                status=AgentStatus(robot_id="a-ok", state=AgentState.RUNNING, digest=D1),
                description=RobotDescription(id="a-ok", recommended_template="turtlebot3-burger"),
            ),
            "c-bad": RobotSeen(
                launch_digest=D1,
                status=AgentStatus(robot_id="c-bad", state=AgentState.FAILED, restarts=5),
            ),
            "z-gone": RobotSeen(
                status=AgentStatus(robot_id="z-gone", state=AgentState.IDLE),
            ),
        }
    )
    rows = build_rows(desired, retained)
    assert [(r.robot_id, r.verdict) for r in rows] == [
        ("c-bad", Verdict.DEGRADED),
        ("b-off", Verdict.OFFLINE),
        ("z-gone", Verdict.UNASSIGNED),
        ("a-ok", Verdict.IN_SYNC),
    ]
    assert rows[0].restarts == 5
    assert rows[-1].warnings == [
        "assigned robot template 'turtlebot3-camera' differs from the robot's recommended "
        "'turtlebot3-burger'"
    ]
    fleet = FleetStatus(rows, None, "test")
    assert not fleet.in_sync
    text = fleet_status_text(fleet)
    assert text.index("c-bad") < text.index("b-off") < text.index("a-ok")
    assert "warning: a-ok: assigned robot template" in text
    assert "no reconciler status on the broker" in text


def test_in_sync_needs_every_assigned_robot_and_a_ready_reconciler() -> None:
    rows = build_rows(
        {"r1": want(), "r2": DesiredRobot("r2", "s", D2, suspended=True)},
        Retained(robots={"r1": seen(AgentState.RUNNING)}),
    )
    ready = ReconcilerStatus(state="Ready", ready=True, last_applied_revision="a" * 40)
    stalled = ReconcilerStatus(
        state="Stalled",
        ready=False,
        reason="BuildFailed",
        failed_revision="b" * 40,
        diagnostics=["configs/fleet.yaml:1:1: error X bad"],
    )
    assert FleetStatus(rows, ready, "t").in_sync
    assert not FleetStatus(rows, stalled, "t").in_sync
    text = fleet_status_text(FleetStatus(rows, stalled, "t"))
    assert "reconciler: Stalled (BuildFailed)" in text and "error X bad" in text
    assert f"failed on {'b' * 12}" in text


def test_no_dead_or_stale_reconciler_is_in_sync() -> None:
    rows = build_rows({"r1": want()}, Retained(robots={"r1": seen(AgentState.RUNNING)}))
    at = 1_000_000.0
    beating = ReconcilerStatus(state="Ready", ready=True, heartbeat=at - 20, interval=30)
    assert FleetStatus(rows, beating, "t", checked_at=at).health is Health.OK
    assert FleetStatus(rows, beating, "t", checked_at=at).in_sync

    missing = FleetStatus(rows, None, "t", checked_at=at)
    assert missing.health is Health.MISSING and not missing.in_sync
    assert "reconciler: MISSING" in fleet_status_text(missing)

    will = ReconcilerStatus(state="Offline", ready=False, reason="Offline", message="it died")
    offline = FleetStatus(rows, will, "t", checked_at=at)
    assert offline.health is Health.OFFLINE and not offline.in_sync
    assert "reconciler: Offline" in fleet_status_text(offline)
    assert offline.as_json()["reconciler_health"] == "offline"

    # Ready, but its heartbeat is 3 intervals (and a minute) overdue: hung or cut off.
    late = beating.model_copy(update={"heartbeat": at - 3 * 30 - 1})
    stale = FleetStatus(rows, late, "t", checked_at=at)
    assert stale.health is Health.STALE and not stale.in_sync
    assert "STALE: its last heartbeat is 91 s old" in fleet_status_text(stale)
    assert stale.as_json()["reconciler_health"] == "stale"
    # An older reconciler without a heartbeat cannot be judged stale.
    old = ReconcilerStatus(state="Ready", ready=True)
    assert FleetStatus(rows, old, "t", checked_at=at).in_sync


def test_unreadable_payloads_are_counted_and_control_characters_escaped() -> None:
    topics = Topics()
    deep = b"[" * 100_000 + b"]" * 100_000
    messages = {
        topics.status("deep"): deep,
        topics.status("dup"): b'{"robot_id": "dup", "state": "running", "state": "idle"}',
        topics.status("utf8"): b'{"robot_id": "utf8", "state": "\xff"}',  # not UTF-8
        topics.status("big"): oversized(2_000_000),
        topics.launch("deep"): b"{" * 50_000,
        topics.description("dup"): b'{"id": "dup", "id": "x"}',
        topics.reconciler_status: deep,
        topics.status("evil"): AgentStatus(
            robot_id="evil", state=AgentState.FAILED, message="\x1b[2Jok\nreconciler: Ready"
        )
        .model_dump_json()
        .encode(),
        topics.description("two\nforged"): b"{}",
        topics.launch("fake"): b"\x00oversized not a size",  # looks like our placeholder
    }
    parsed = parse_retained(messages, topics)
    assert parsed.ignored == {"status": 4, "launch": 2, "description": 2, "reconciler-status": 1}
    assert parsed.reconciler is None
    assert set(parsed.robots) == {"deep", "dup", "utf8", "big", "evil", "two\nforged", "fake"}
    assert all(parsed.robots[r].status is None for r in ("deep", "dup", "utf8", "big"))
    desired = {"evil": DesiredRobot("evil", "s", D1)}
    fleet = FleetStatus(build_rows(desired, parsed), None, "t", ignored=parsed.ignored)
    text = fleet_status_text(fleet)
    assert "\x1b" not in text and "\\x1b[2Jok\\nreconciler: Ready" in text
    assert "\nforged" not in text and "two\\nforged" in text
    assert "unreadable retained payloads skipped: 2 description, 2 launch" in text


def test_a_retained_stop_is_unassigned() -> None:
    topics = Topics()
    stop = StopRequest(robot_id="r1", revision="c" * 40, issued_at=1.0, signature="AA==")
    idle = AgentStatus(robot_id="r1", state=AgentState.IDLE)
    parsed = parse_retained(
        {
            topics.launch("r1"): stop.payload(),
            topics.status("r1"): idle.model_dump_json().encode(),
        },
        topics,
    )
    assert parsed.ignored == {} and parsed.robots["r1"].stopped
    assert [(r.robot_id, r.verdict) for r in build_rows({}, parsed)] == [("r1", Verdict.UNASSIGNED)]
    # Assigned again: its request is on its way.
    assert verdict(want(), parsed.robots["r1"])[0] is Verdict.PROGRESSING


def test_parse_retained_sorts_topics_and_skips_garbage() -> None:
    topics = Topics("lab")
    status = AgentStatus(robot_id="r1", state=AgentState.RUNNING, digest=D1)
    messages = {
        topics.status("r1"): status.model_dump_json().encode(),
        topics.launch("r1"): b'{"digest": "' + D1.encode() + b'"}',  # not a full request
        topics.status("r2"): b"not json",
        topics.reconciler_status: ReconcilerStatus(state="Ready", ready=True)
        .model_dump_json()
        .encode(),
        "elsewhere/robots/r3/status": status.model_dump_json().encode(),
    }
    parsed = parse_retained(messages, topics)
    assert set(parsed.robots) == {"r1", "r2"}
    assert parsed.robots["r1"].status == status
    assert parsed.robots["r1"].launch_digest == D1 and parsed.robots["r1"].launch is None
    assert parsed.robots["r2"].status is None
    assert parsed.reconciler is not None and parsed.reconciler.ready


def test_text_from_the_broker_is_never_rich_markup_and_never_wrapped() -> None:
    long_reason = "brain failed: " + "x" * 400
    status = AgentStatus(
        robot_id="[bold]r1", state=AgentState.FAILED, message=f"[red]{long_reason}[/red]"
    )
    retained = Retained(robots={"[bold]r1": RobotSeen(launch_digest=D1, status=status)})
    desired = {"[bold]r1": DesiredRobot("[bold]r1", "[link=http://x]s[/link]", D1)}
    text = fleet_status_text(FleetStatus(build_rows(desired, retained), None, "[i]repo[/i]"))
    assert "\x1b" not in text
    row = next(line for line in text.splitlines() if "Degraded" in line)
    assert row.startswith("[bold]r1 ")
    assert "[link=http://x]s[/link]" in row and f"[red]{long_reason}[/red]" in row
    assert "desired: [i]repo[/i]" in text
    assert all(line == line.rstrip() for line in text.splitlines())


def test_a_label_selector_keeps_only_the_robots_it_matches() -> None:
    desired = {
        "a": DesiredRobot("a", "s", D1, labels={"ring": "canary", "site": "x"}),
        "b": DesiredRobot("b", "s", D1, labels={"site": "x"}),
    }
    fleet = FleetStatus(build_rows(desired, Retained()), None, "t")
    only = fleet.select({"ring": "canary"})
    assert [r.robot_id for r in only.rows] == ["a"]
    assert "only robots labelled ring=canary: 1 of 2" in only.notes
    assert [r.robot_id for r in fleet.select({"site": "x"}).rows] == ["a", "b"]
    assert fleet.select({}) is fleet


def test_a_selector_option_is_key_equals_value() -> None:
    from robotconf.contract.errors import CliError
    from robotconf.workstation.cli.status import parse_selector

    assert parse_selector(("ring=canary", "site=hall-a")) == {"ring": "canary", "site": "hall-a"}
    for bad in ("ring", "ring=", "=x", "a b=c", "ring=can ary"):
        with pytest.raises(CliError):
            parse_selector((bad,))


def test_a_deferred_robot_is_progressing_and_says_what_waits_since_when() -> None:
    waits = "restart for request sha256:2 deferred by the brain's hold file since 21:04:05 UTC"
    status = AgentStatus(
        robot_id="r1", state=AgentState.DEFERRED, digest=D1, message=waits, deferred_since=5.0
    )
    moving = RobotSeen(launch_digest=D2, status=status)
    assert moving.online and moving.brain_active  # online, its brain runs the old request
    assert verdict(want(D2), moving) == (Verdict.PROGRESSING, waits)
    # A restart from the desk waits: on the desired request, still not done.
    assert verdict(want(D1), RobotSeen(launch_digest=D1, status=status))[0] is (Verdict.PROGRESSING)
    leaving = RobotSeen(launch_digest=None, status=status)
    assert verdict(None, leaving) == (
        Verdict.PROGRESSING,
        "not in fleet.yaml: its brain's hold file defers its stop",
    )
    rows = build_rows({"r1": want(D2)}, Retained(robots={"r1": moving}))
    assert rows[0].as_json()["deferred_since"] == 5.0 and rows[0].state == "deferred"
    text = fleet_status_text(FleetStatus(rows, None, "test"))
    assert " deferred " in text and "since 21:04:05 UTC" in text
