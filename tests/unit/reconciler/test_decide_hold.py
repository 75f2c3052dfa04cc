"""The `drift: hold` policy, pure: a robot whose new request does not fit the interfaces it
reports keeps what it holds until they fit; `warn` delivers; unknown interfaces never hold."""

from __future__ import annotations

from robotconf.configurator.render import FleetRender, render_fleet
from robotconf.contract.interfaces import Interface, RobotInterfaces
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.reconciler.decide import Observation, Reason, decide
from robotconf.reconciler.desired import Desired
from robotconf.reconciler.report import Followed, status_of
from robotconf.reconciler.rollout import RolloutInput, roll_out
from tests.support.fleet import ROBOTS
from tests.support.lab import Lab

HEAD = "h" * 40
# tb3-04 runs patrol-real: navigate_with_nav2 needs the /navigate_to_pose action and /odom.
ODOM = Interface(name="/odom", type="nav_msgs/msg/Odometry")
NAV2 = Interface(name="/navigate_to_pose", type="nav2_msgs/action/NavigateToPose")
LACKING = RobotInterfaces(topics=[ODOM], source="ros2")
FITTING = RobotInterfaces(topics=[ODOM], actions=[NAV2], source="ros2")


def build(lab: Lab, policy: str | None, extra: str = "") -> Desired:
    if policy is not None:
        lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml") + f"drift: {policy}\n")
    if extra:
        lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml") + extra)
    checked = lab.check()
    assert checked.ok, checked.errors
    return Desired(HEAD, render_fleet(checked.repo))


def fleet_of(desired: Desired) -> FleetRender:
    assert desired.fleet is not None
    return desired.fleet


def test_hold_keeps_a_robot_whose_new_request_does_not_fit_and_says_why(lab: Lab) -> None:
    head = build(lab, "hold")
    old = {r: "sha256:" + "0" * 64 for r in ROBOTS}  # every robot holds an older request
    seen = Observation(head=HEAD, build=head, launches=old, interfaces={"tb3-04": LACKING})
    decision = decide(seen)
    assert decision.actions is not None
    assert sorted(decision.actions.publish) == sorted(set(ROBOTS) - {"tb3-04"})
    condition = decision.condition
    assert condition.reason is Reason.APPLIED
    (held,) = condition.held
    assert held.robot == "tb3-04"
    assert held.reason == (
        "lacks /navigate_to_pose (nav2_msgs/action/NavigateToPose), needed by "
        "navigate_with_nav2 via action client mapping navigate_to_pose"
    )
    assert "1 robot(s) held for drift (drift: hold): tb3-04" in condition.message
    status = status_of(
        condition,
        decision.actions,
        serving=head,
        head=HEAD,
        previous=None,
        followed=Followed("main", "/lab", 30.0),
    )
    assert [h.robot for h in status.held] == ["tb3-04"] and status.more_held == 0

    # Its interfaces fit: it gets its request.
    fits = decide(Observation(head=HEAD, build=head, launches=old, interfaces={"tb3-04": FITTING}))
    assert fits.actions is not None and "tb3-04" in fits.actions.publish
    assert fits.condition.held == ()


def test_warn_delivers_and_unknown_or_failed_interfaces_never_hold(lab: Lab) -> None:
    warn = build(lab, None)  # the default
    assert fleet_of(warn).drift == "warn"
    seen = Observation(head=HEAD, build=warn, launches={}, interfaces={"tb3-04": LACKING})
    decision = decide(seen)
    assert decision.actions is not None and "tb3-04" in decision.actions.publish
    assert decision.condition.held == ()

    hold = build(lab, "hold")
    failed = RobotInterfaces(source="ros2", error="ros2 timed out")
    for interfaces in ({}, {"tb3-04": failed}):
        decision = decide(Observation(head=HEAD, build=hold, launches={}, interfaces=interfaces))
        assert decision.actions is not None and "tb3-04" in decision.actions.publish
        assert decision.condition.held == ()


def test_a_request_delivered_already_is_not_held_nor_cleared(lab: Lab) -> None:
    hold = build(lab, "hold")
    launches = {r: req.digest for r, req in fleet_of(hold).requests.items()}
    decision = decide(
        Observation(head=HEAD, build=hold, launches=launches, interfaces={"tb3-04": LACKING})
    )
    assert decision.actions is not None and decision.actions.empty
    assert decision.condition.held == ()


def test_a_held_robot_is_absent_from_its_wave_never_failed(lab: Lab) -> None:
    policy = (
        "rollout:\n  waves: [{name: all}]\n  healthy_after: 1\n  wave_timeout: 10\n"
        "  max_failures: 0\n"
    )
    head = fleet_of(build(lab, "hold", policy))
    head.revision = HEAD
    online = {
        r: AgentStatus(robot_id=r, state=AgentState.RUNNING, digest="sha256:" + "0" * 64)
        for r in ROBOTS
    }
    old = {r: "sha256:" + "0" * 64 for r in ROBOTS}
    first = roll_out(
        RolloutInput(
            head=head,
            stable=None,
            previous=None,
            launches=old,
            statuses=online,
            running_since={},
            now=0.0,
            held=frozenset({"tb3-04"}),
        )
    )
    assert first.status is not None and "tb3-04" in first.status.pending
    # At the wave's timeout the others (never delivered here, online) failed; tb3-04 did not.
    late = roll_out(
        RolloutInput(
            head=head,
            stable=None,
            previous=first.status,
            launches=old,
            statuses=online,
            running_since={},
            now=100.0,
            record=first.record,
            held=frozenset({"tb3-04"}),
        )
    )
    assert late.status is not None
    assert "tb3-04" not in late.status.failed and "tb3-01" in late.status.failed

    # decide() passes who is held into the wave and leaves that robot's topic alone.
    hold = Desired(HEAD, head)
    decision = decide(
        Observation(
            head=HEAD,
            build=hold,
            launches=old,
            statuses=online,
            now=0.0,
            interfaces={"tb3-04": LACKING},
        )
    )
    assert decision.actions is not None and "tb3-04" not in decision.actions.publish
    assert [h.robot for h in decision.condition.held] == ["tb3-04"]
    assert decision.condition.rollout is not None
    assert "tb3-04" in decision.condition.rollout.pending


def test_a_robot_whose_wave_has_not_come_is_waiting_not_held(lab: Lab) -> None:
    policy = (
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        "  healthy_after: 1\n  wave_timeout: 10\n"
    )
    head = build(lab, "hold", policy)
    fleet_of(head).revision = HEAD
    old = {r: "sha256:" + "0" * 64 for r in ROBOTS}
    online = {r: AgentStatus(robot_id=r, state=AgentState.RUNNING, digest=old[r]) for r in ROBOTS}
    decision = decide(
        Observation(
            head=HEAD,
            build=head,
            launches=old,
            statuses=online,
            now=0.0,
            interfaces={"tb3-04": LACKING},
        )
    )
    assert decision.actions is not None and "tb3-04" not in decision.actions.publish
    assert decision.condition.held == ()  # tb3-04 (wave `all`) waits for its wave
