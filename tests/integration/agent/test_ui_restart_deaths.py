"""`robotconf ui` killed (SIGKILL, a real process) while a restart it sent is in flight: the
robot is busy, so the restart waits for the brain's hold. The restart is carried out once
when the hold lifts — never again by a UI started anew — and the audit survives the UI: its
log has the ask, written before it was sent, and the new UI shows the robot's last restart
and who asked for it (the robot's own status)."""

from __future__ import annotations

import re
import signal
from pathlib import Path
from typing import Any

from robotconf.contract.wire import AgentState, AgentStatus
from tests.integration.agent.conftest import AgentFactory
from tests.integration.agent.test_agent_busy import busy_agent, deferred, run_held
from tests.integration.agent.test_ui_operator import TOKEN, ui_factory  # noqa: F401 (fixture)
from tests.support.agents import ROBOT, make_request
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

BEARER = {"Authorization": f"Bearer {TOKEN}"}


def restarts_by(watch: FleetWatch, by: str, since: int = 0) -> set[float]:
    """The distinct restarts by `by` the robot's statuses recorded (their issue times)."""
    return {
        s.restart_requested_at
        for s in watch.history(ROBOT)[since:]
        if s.restart_requested_by == by and s.restart_requested_at is not None
    }


def running_pids(watch: FleetWatch, since: int) -> list[int]:
    pids: list[int] = []
    for status in watch.history(ROBOT)[since:]:
        if status.state is AgentState.RUNNING and status.pid and status.pid not in pids:
            pids.append(status.pid)
    return pids


def test_a_ui_killed_while_its_restart_waits_loses_neither_the_restart_nor_its_audit(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    make_agent: AgentFactory,
    ui_factory: Any,  # noqa: F811
    tmp_path: Path,
) -> None:
    agent, marker = busy_agent(make_agent, tmp_path)
    request = make_request()
    first = run_held(agent, watch, mosquitto, request.payload(), request.digest)
    ui = ui_factory()
    asked = ui.ask("POST", f"/robots/{ROBOT}/restart", b"", **BEARER)
    assert asked.code == 303, asked.body
    # In flight: the agent took it and defers it while the brain holds.
    status: AgentStatus = deferred(watch, agent, first, "restart requested by ui.bearer")
    seen = len(watch.history(ROBOT)) - 1
    ui.proc.send_signal(signal.SIGKILL)
    ui.proc.wait()
    assert re.search(rf"ui: restart of {ROBOT} asked by ui\.bearer", ui.stderr())
    marker.unlink()  # the hold lifts: the restart the dead UI sent is carried out
    second = watch.wait_for(
        ROBOT,
        lambda s: s.state is AgentState.RUNNING and s.pid != first.pid,
        "the restart carried out",
        agent=agent,
    )
    agent.note_brain(second.pid)
    assert second.restart_requested_by == "ui.bearer"
    assert second.restart_requested_at == status.restart_requested_at
    # A UI started anew sends nothing by itself, and shows what the robot did and who asked.
    again = ui_factory()
    page = wait_for(
        lambda: (
            (body := again.ask("GET", f"/robots/{ROBOT}", **BEARER).body)
            and "Last restart" in body
            and body
        ),
        "the robot's last restart on the new UI's page",
    )
    assert f"restart: {ROBOT} by ui.bearer at" in page
    done = again.ask("POST", f"/robots/{ROBOT}/restart", b"", **BEARER)
    assert done.code == 303, done.body
    third = watch.wait_for(
        ROBOT,
        lambda s: s.state is AgentState.RUNNING and s.pid not in (first.pid, second.pid),
        "the second restart carried out",
        agent=agent,
    )
    agent.note_brain(third.pid)
    # Each restart once: two asked, two carried out (two new brains), none twice.
    assert len(restarts_by(watch, "ui.bearer", seen)) == 2
    assert running_pids(watch, seen) == [second.pid, third.pid]
