"""The supervisor's phases change only along TRANSITIONS, through its one `_move`; how a brain
ended is retried or terminal as ENDING_RULES say."""

from __future__ import annotations

import ast
import itertools
from pathlib import Path

import pytest

from robotconf.agent.supervisor import (
    ENDING_RULES,
    TRANSITIONS,
    Ending,
    Policy,
    Supervisor,
    legal,
    retried,
)
from robotconf.contract.wire import AgentState

ROOT = Path(__file__).resolve().parents[3]
PHASES = [s for s in AgentState if s not in (AgentState.REJECTED, AgentState.OFFLINE)]
LEGAL = [(a, b) for a, targets in TRANSITIONS.items() for b in sorted(targets)]
ILLEGAL = [
    (a, b) for a, b in itertools.product(PHASES, PHASES) if a != b and b not in TRANSITIONS[a]
]


def at(phase: AgentState) -> Supervisor:
    sup = Supervisor("tb3-01", Policy(), wall_clock=lambda: 1_000.0)
    sup._phase = phase  # placed there by the test: the move under test is the next one
    return sup


def test_the_table_names_every_phase_and_only_phases() -> None:
    assert set(TRANSITIONS) == set(PHASES)
    assert all(targets <= set(PHASES) for targets in TRANSITIONS.values())
    assert all(a not in targets for a, targets in TRANSITIONS.items())  # staying is implied
    # Every phase is reachable from idle, and idle from every phase but idle itself.
    reached, todo = {AgentState.IDLE}, [AgentState.IDLE]
    while todo:
        for nxt in TRANSITIONS[todo.pop()] - reached:
            reached.add(nxt)
            todo.append(nxt)
    assert reached == set(PHASES)


@pytest.mark.parametrize(("before", "after"), LEGAL)
def test_every_legal_change_is_made(before: AgentState, after: AgentState) -> None:
    sup = at(before)
    assert legal(before, after) and sup._move(after)
    assert sup.phase is after


@pytest.mark.parametrize("phase", PHASES)
def test_staying_is_always_legal(phase: AgentState) -> None:
    assert at(phase)._move(phase)


@pytest.mark.parametrize(("before", "after"), ILLEGAL)
def test_an_illegal_change_is_refused_and_logged(
    before: AgentState, after: AgentState, caplog: pytest.LogCaptureFixture
) -> None:
    sup = at(before)
    message = sup.message
    sup._enter(after, "should not be said")
    assert not legal(before, after)
    assert (sup.phase, sup.message) == (before, message)
    assert [r.getMessage() for r in caplog.records] == [
        f"illegal phase change of tb3-01 refused: {before.value} -> {after.value} "
        "(agent/supervisor.py TRANSITIONS)"
    ]
    caplog.clear()  # refused on purpose: the agent tests' guard is for paths that do it


def test_the_phase_cannot_be_set_from_outside() -> None:
    with pytest.raises(AttributeError):
        at(AgentState.IDLE).phase = AgentState.RUNNING  # type: ignore[misc]


def assignments_of_phase(source: str) -> list[str]:
    """Where `source` assigns an attribute named phase or _phase, as `function:line`."""
    found: list[str] = []
    for func in ast.walk(ast.parse(source)):
        if not isinstance(func, ast.FunctionDef):
            continue
        for node in ast.walk(func):
            targets: list[ast.expr] = []
            if isinstance(node, ast.Assign):
                targets = node.targets
            elif isinstance(node, ast.AugAssign | ast.AnnAssign):
                targets = [node.target]
            found += [
                f"{func.name}:{getattr(node, 'lineno', 0)}"
                for t in targets
                if isinstance(t, ast.Attribute) and t.attr in ("phase", "_phase")
            ]
    return found


def test_only_move_changes_the_phase() -> None:
    """Read from the code: besides `__init__`'s first phase, `_move` alone assigns it, in
    agent/ as a whole."""
    found = [
        f"{path.name}:{where}"
        for path in sorted((ROOT / "agent").glob("*.py"))
        for where in assignments_of_phase(path.read_text(encoding="utf-8"))
    ]
    assert [f.rsplit(":", 1)[0] for f in found] == [
        "supervisor.py:__init__",
        "supervisor.py:_move",
    ], found
    sample = "class S:\n    def f(self):\n        self.phase = 1\n        self._phase += 1\n"
    assert assignments_of_phase(sample) == ["f:3", "f:4"]


@pytest.mark.parametrize(
    ("ending", "restart", "expected"),
    [
        (Ending.CRASHED, "on-failure", True),
        (Ending.CRASHED, "always", True),
        (Ending.CRASHED, "never", False),
        (Ending.UNREADY, "on-failure", True),
        (Ending.UNREADY, "always", True),
        (Ending.UNREADY, "never", False),
        (Ending.CLEAN, "on-failure", False),
        (Ending.CLEAN, "always", True),
        (Ending.CLEAN, "never", False),
        (Ending.SPAWN_FAILED, "on-failure", False),
        (Ending.SPAWN_FAILED, "always", False),
        (Ending.SPAWN_FAILED, "never", False),
    ],
)
def test_each_ending_is_retried_or_terminal_by_the_table(
    ending: Ending, restart: str, expected: bool
) -> None:
    assert retried(ending, restart) is expected  # type: ignore[arg-type]


def test_every_ending_has_a_rule_and_rests_in_a_phase_a_brain_may_end_in() -> None:
    assert set(ENDING_RULES) == set(Ending)
    for rule in ENDING_RULES.values():
        assert rule.terminal in TRANSITIONS[AgentState.RUNNING] | {AgentState.FAILED}
        assert rule.terminal in (AgentState.FAILED, AgentState.EXITED)
