"""When a changed status is published: the one rule that holds a status back (no broker)."""

from __future__ import annotations

from robotconf.agent.status_report import STOPPING_QUIET, publish_delay
from robotconf.contract.wire import AgentState, AgentStatus


def status(state: AgentState, message: str = "") -> AgentStatus:
    return AgentStatus(robot_id="tb3-01", state=state, seq=1, message=message)


def test_a_fresh_stopping_waits_for_the_brain_to_be_gone() -> None:
    assert publish_delay(status(AgentState.STOPPING), status(AgentState.RUNNING)) == STOPPING_QUIET
    assert publish_delay(status(AgentState.STOPPING), None) == STOPPING_QUIET


def test_a_stopping_already_reported_is_updated_at_once() -> None:
    killed = status(AgentState.STOPPING, "sent SIGKILL")
    assert publish_delay(killed, status(AgentState.STOPPING, "stopping")) == 0.0


def test_every_other_state_goes_at_once() -> None:
    for state in AgentState:
        if state is not AgentState.STOPPING:
            assert publish_delay(status(state), status(AgentState.STOPPING)) == 0.0
            assert publish_delay(status(state), None) == 0.0


def test_refusals_are_logged_a_few_at_a_time_with_a_count_of_the_rest() -> None:
    from robotconf.contract.throttle import Throttle

    throttle = Throttle(10.0, limit=2)
    assert throttle.admit("a", 0.0) == "a"
    assert throttle.admit("b", 1.0) == "b"
    assert [throttle.admit("flood", 2.0 + n / 100) for n in range(50)] == [None] * 50
    assert throttle.admit("c", 10.5) == "c (and 50 more not logged)"
    assert throttle.admit("d", 10.6) is None
