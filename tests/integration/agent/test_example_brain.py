"""The how-to's example brain (examples/brains/patrol_brain.py) works as the page says: alone on
a request file, its reports printed as the wire's lines; under a real agent and Mosquitto, its
goals counted in the robot's summary and its outcomes streamed; and the page shows the file as
it is."""

from __future__ import annotations

import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from pydantic import TypeAdapter

from robotconf.contract.goals import BrainMessage, GoalLine, OutcomeState, Ready
from robotconf.contract.launch import LaunchGoal, LaunchRequest, make_launch_request
from robotconf.contract.wire import AgentState, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, make_request, publish
from tests.support.goals_watch import GoalsWatch
from tests.support.lab import ROOT
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch

EXAMPLE = ROOT / "examples" / "brains" / "patrol_brain.py"
PAGE = ROOT / "docs" / "how-to" / "write-a-brain.md"
MESSAGE: TypeAdapter[object] = TypeAdapter(BrainMessage)


def patrol_request() -> LaunchRequest:
    """Two goals: one with a location (it succeeds), one without (it fails: NO_LOCATION)."""
    base = make_request()
    goals = [LaunchGoal(task="Delivery", location={"x": 1.0}), LaunchGoal(task="Patrol")]
    scenario = base.scenario.model_copy(update={"goals": goals})
    return make_launch_request(ROBOT, base.robot_name, base.revision, scenario)


def test_the_page_shows_the_example_as_it_is() -> None:
    code = EXAMPLE.read_text(encoding="utf-8")
    assert f"```python\n{code}```" in PAGE.read_text(encoding="utf-8")
    lines = [line for line in code.splitlines() if line.strip() and not line.startswith('"""')]
    assert len(lines) <= 32  # "a brain in 30 lines", imports and blanks aside more or less


def test_alone_on_a_request_file_it_prints_the_wire_s_lines(tmp_path: Path) -> None:
    path = tmp_path / "request.json"
    path.write_bytes(patrol_request().payload())
    brain = subprocess.Popen(
        [sys.executable, str(EXAMPLE), str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert brain.stderr is not None
    # Its lines are read as they come, until the second goal has ended (two goals of 2 s each;
    # a loaded machine takes longer), and only then is it stopped.
    lines: list[str] = []
    deadline = time.monotonic() + 60
    while not any('"task":"Patrol"' in line and '"failed"' in line for line in lines):
        assert time.monotonic() < deadline, f"the Patrol goal never ended: {lines}"
        ready, _, _ = select.select([brain.stderr], [], [], 1.0)
        if ready:
            line = brain.stderr.readline()
            assert line, f"the brain ended early: {lines}"
            lines.append(line)
    brain.send_signal(signal.SIGTERM)
    out, err = brain.communicate(timeout=30)
    assert brain.returncode == 0, err
    assert out.startswith(f"{ROBOT} runs delivery-gazebo at rev-1")
    said = [MESSAGE.validate_json(line) for line in [*lines, *err.splitlines()]]
    assert isinstance(said[0], Ready)
    ends = [(m.task, m.state, m.code) for m in said if isinstance(m, GoalLine)]
    assert ("Delivery", "succeeded", None) in ends
    assert ("Patrol", "failed", "NO_LOCATION") in ends


def test_under_an_agent_its_goals_are_counted_and_streamed(
    mosquitto: Mosquitto, watch: FleetWatch, goals: GoalsWatch, make_agent: AgentFactory
) -> None:
    agent = make_agent(command=[sys.executable, str(EXAMPLE), "{launch_request}"]).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    request = patrol_request()
    publish(mosquitto.url, Topics().launch(ROBOT), request.payload())
    watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=request.digest)
    summary = goals.wait_summary(
        ROBOT, lambda s: s.completed >= 1 and s.failed >= 1, "a goal succeeded, one failed"
    )
    assert summary.ready is True and summary.digest == request.digest
    assert summary.vitals.get("battery") == 0.9
    records = goals.wait_records(ROBOT, 2)
    assert {(r.task, r.outcome) for r in records[:2]} == {
        ("Delivery", OutcomeState.SUCCEEDED),
        ("Patrol", OutcomeState.FAILED),
    }
    assert all(r.revision == "rev-1" and r.digest == request.digest for r in records)
