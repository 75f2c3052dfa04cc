"""The agent's dispatch tables: every event the inbox carries has a handler, every effect the
supervisor asks for has one, and nothing else is in them (no broker)."""

from __future__ import annotations

import typing
from pathlib import Path

from robotconf.agent.brain_runner import EFFECTS
from robotconf.agent.config import parse_config
from robotconf.agent.events import Event
from robotconf.agent.runtime import HANDLERS, Agent
from robotconf.agent.supervisor import Effect


def test_every_event_the_inbox_carries_has_one_handler() -> None:
    carried = set(typing.get_args(Event))
    assert len(carried) >= 9  # the union was read: an empty one would make this pass
    assert set(HANDLERS) == carried


def test_every_effect_the_supervisor_asks_for_has_one_handler() -> None:
    asked = set(typing.get_args(Effect))
    assert len(asked) >= 4
    assert set(EFFECTS) == asked


def test_each_handler_is_a_method_of_its_own() -> None:
    """A copied line that sends two events to one handler is a slip, not a design."""
    assert len(set(HANDLERS.values())) == len(HANDLERS)
    assert len(set(EFFECTS.values())) == len(EFFECTS)


def test_an_event_without_a_handler_is_reported_and_the_agent_goes_on(tmp_path: Path) -> None:
    """Should an event reach the loop without a table entry, it is an internal error said in
    the status and the log, never an exception out of the loop."""
    text = (
        "broker: mqtt://127.0.0.1:1\n"
        "description: {id: tb3-01}\n"
        "command: [brain, '{launch_request}']\n"
        f"workdir: {tmp_path / 'work'}\n"
    )
    agent = Agent(parse_config(text, "agent.yaml"))
    try:
        agent._handle_guarded(Unhandled(), 0.0)  # type: ignore[arg-type]
        assert agent.supervisor.message == "internal error (KeyError); see the agent log"
    finally:
        agent.inbox.close()


class Unhandled:
    """An event type no table names."""
