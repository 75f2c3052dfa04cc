"""The agent's dispatch tables: every event the inbox carries has a handler, every effect the
supervisor asks for has one, and nothing else is in them (no broker)."""

from __future__ import annotations

import typing

from agent.brain_runner import EFFECTS
from agent.events import Event
from agent.runtime import HANDLERS
from agent.supervisor import Effect


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
