"""The agent relays its brain's goals, vitals and events, bounded (issue 30, item 2): real agents,
real Mosquitto, and a test brain that writes raw JSON lines to the socket (not the library)."""

from __future__ import annotations

import json
import os
import signal
import stat
import sys
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from robotconf.contract.goals import MAX_TEXT, GoalsSummary, OutcomeRecord, OutcomeState
from robotconf.contract.wire import AgentState, Topics
from tests.integration.agent.conftest import AgentFactory
from tests.support.agents import ROBOT, AgentProc, make_request, publish
from tests.support.goals_watch import GoalsWatch
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

RAW_BRAIN = Path(__file__).resolve().parents[2] / "support" / "raw_brain.py"
LAUNCH = Topics().launch(ROBOT)

HELLO = '{"type": "hello", "digest": "{digest}", "pid": {pid}, "library": "raw-test/1"}'
READY = '{"type": "ready"}'


def line(**fields: Any) -> dict[str, str]:
    return {"send": json.dumps(fields)}


def goal(id: str, task: str, state: str, **more: Any) -> dict[str, str]:
    return line(type="goal", id=id, task=task, state=state, **more)


def raw_agent(
    make_agent: AgentFactory,
    tmp_path: Path,
    plan: list[dict[str, Any]],
    name: str = "agent",
    **settings: Any,
) -> AgentProc:
    """An agent whose brain follows `plan` (tests/support/raw_brain.py)."""
    plan_path = tmp_path / f"{name}-plan.json"
    plan_path.write_text(json.dumps(plan), encoding="utf-8")
    command = [sys.executable, str(RAW_BRAIN), str(plan_path), "{launch_request}"]
    return make_agent(name, command=command, **settings)


def launch(mosquitto: Mosquitto, variant: int = 0, robot: str = ROBOT) -> str:
    request = make_request(robot_id=robot, variant=variant)
    publish(mosquitto.url, Topics().launch(robot), request.payload())
    return request.digest


def test_a_brain_that_says_hello_is_starting_until_ready_and_its_goals_are_relayed(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    plan = [
        {"send": HELLO},
        {"sleep": 4.0},  # past startsecs: without its hello it would be running by now
        {"send": READY},
        goal("g1", "Delivery", "started"),
        goal("g1", "Delivery", "progress", fraction=0.5, eta=3.0, note="halfway"),
        goal("g1", "Delivery", "succeeded"),
        goal("g2", "Delivery", "started"),
        goal("g2", "Delivery", "failed", code="NAV2_TIMEOUT", message="blocked at the door"),
        goal("g3", "Patrol", "started"),
        goal("g3", "Patrol", "canceled"),
        goal("g4", "Patrol", "started"),
        goal("g4", "Patrol", "progress", fraction=0.25, eta=40.0),
        line(type="vitals", values={"battery": 0.82, "pose": "1.0,2.0", "docked": False}),
        line(type="event", severity="info", message="all good"),
    ]
    # startsecs long enough for the hello to come first on a loaded machine (a brain's
    # Python can take over a second to start there); the plan's sleep outlasts it.
    agent = raw_agent(make_agent, tmp_path, plan, startsecs=2.0)
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    hello = watch.wait_for(
        ROBOT,
        lambda s: s.state is AgentState.STARTING and "said hello" in s.message,
        "starting, waiting for ready",
        agent=agent,
    )
    agent.note_brain(hello.pid)
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest)
    assert running.pid == hello.pid and "ready" in running.message
    # Between its start and its ready, never running: startsecs (2 s) did not count.
    started = [s for s in watch.history(ROBOT) if s.pid == hello.pid]
    assert [s.state for s in started].index(AgentState.RUNNING) == len(started) - 1

    summary = goals.wait_summary(
        ROBOT, lambda s: s.canceled == 1 and s.underway == 1 and bool(s.events), "the goals"
    )
    check_summary(summary, digest)
    check_records(goals.wait_records(ROBOT, 3), summary, digest)
    assert not any(goals.retained_flags), "outcome records are a stream, never retained"


def check_summary(summary: GoalsSummary, digest: str) -> None:
    """The summary of the plan of the test above."""
    assert summary.reporting and summary.ready is True and summary.dropped == 0
    assert (summary.digest, summary.revision, summary.scenario) == (
        digest,
        "rev-1",
        "delivery-gazebo",
    )
    assert (summary.completed, summary.failed, summary.canceled, summary.stale) == (1, 1, 1, 0)
    assert summary.tasks["Delivery"].completed == 1 and summary.tasks["Delivery"].failed == 1
    assert summary.tasks["Patrol"].canceled == 1 and summary.tasks["Patrol"].underway == 1
    assert summary.current is not None and summary.current.goal == "g4"
    assert summary.current.fraction == 0.25 and summary.current.eta == 40.0
    assert summary.last is not None and summary.last.outcome is OutcomeState.CANCELED
    assert [r.goal for r in summary.recent] == ["g1", "g2", "g3"]
    assert summary.recent[1].code == "NAV2_TIMEOUT"
    assert summary.recent[1].message == "blocked at the door"
    assert summary.vitals == {"battery": 0.82, "pose": "1.0,2.0", "docked": False}
    assert summary.events[-1].message == "all good"


def check_records(records: list[OutcomeRecord], summary: GoalsSummary, digest: str) -> None:
    assert [(r.goal, r.outcome, r.seq) for r in records] == [
        ("g1", OutcomeState.SUCCEEDED, 0),
        ("g2", OutcomeState.FAILED, 1),
        ("g3", OutcomeState.CANCELED, 2),
    ]
    assert {(r.run, r.digest, r.revision, r.scenario) for r in records} == {
        (summary.run, digest, "rev-1", "delivery-gazebo")
    }
    assert records[1].code == "NAV2_TIMEOUT" and records[0].duration is not None


def test_a_brain_that_never_says_hello_keeps_startsecs_and_its_goals_are_unknown(
    mosquitto: Mosquitto, watch: FleetWatch, goals: GoalsWatch, make_agent: AgentFactory
) -> None:
    # A brain that knows nothing of the library (the stand-in speaks it now).
    silent = [sys.executable, "-c", "import time; time.sleep(3600)", "{launch_request}"]
    agent = make_agent(command=silent).start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    running = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest)
    agent.note_brain(running.pid)
    summary = goals.wait_summary(
        ROBOT, lambda s: s.digest == digest and s.run is not None, "a summary of the run"
    )
    assert not summary.reporting and summary.ready is None
    assert (summary.completed, summary.failed, summary.underway) == (0, 0, 0)
    socket_path = agent.workdir / "brain.sock"
    assert stat.S_ISSOCK(socket_path.lstat().st_mode)
    assert stat.S_IMODE(socket_path.lstat().st_mode) == 0o600


def test_a_brain_that_says_hello_but_never_ready_is_stopped_as_a_failed_start(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    # startsecs long enough for the hello to come first on a loaded machine: a brain counted
    # running at startsecs before its hello is `running` for a moment (documented).
    agent = raw_agent(make_agent, tmp_path, [{"send": HELLO}], ready_timeout=1.0, startsecs=5.0)
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    failed = watch.wait_for(
        ROBOT,
        lambda s: s.state is AgentState.FAILED,
        "failed after the restarts",
        agent=agent,
        timeout=60,
    )
    assert "not ready within 1 s (ready_timeout)" in failed.message
    assert "gave up after 3 restarts" in failed.message and failed.digest == digest
    assert not any(s.state is AgentState.RUNNING for s in watch.history(ROBOT))
    stopping = [s for s in watch.history(ROBOT) if s.state is AgentState.BACKOFF]
    assert stopping and "not ready within" in stopping[0].message
    # Its goals were never failed: the runs ended with nothing underway.
    summary = goals.wait_summary(ROBOT, lambda s: not s.reporting, "not reporting")
    assert summary.failed == 0


def test_a_stale_goal_is_reported_once_and_may_still_end(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    plan = [
        {"send": HELLO},
        {"send": READY},
        goal("slow", "Delivery", "started"),
        {"sleep": 3.0},  # stale_after is 0.5 s
        goal("slow", "Delivery", "progress", fraction=0.9),
        goal("slow", "Delivery", "succeeded"),
    ]
    agent = raw_agent(make_agent, tmp_path, plan, goals={"stale_after": 0.5})
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    agent.note_brain(watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest).pid)
    stale = goals.wait_summary(ROBOT, lambda s: s.stale == 1, "the goal stale")
    assert stale.underway == 0 and stale.current is not None and stale.current.stale
    ended = goals.wait_summary(ROBOT, lambda s: s.completed == 1, "the goal ended after all")
    assert ended.stale == 0 and ended.current is None
    records = goals.wait_records(ROBOT, 2)
    assert [(r.goal, r.outcome) for r in records] == [
        ("slow", OutcomeState.STALE),
        ("slow", OutcomeState.SUCCEEDED),
    ]
    assert records[0].seq < records[1].seq and records[0].run == records[1].run


def test_counts_start_again_with_a_new_request_and_survive_a_brain_restart(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    plan = [
        {"send": HELLO},
        {"send": READY},
        goal("a", "Delivery", "started"),
        goal("a", "Delivery", "succeeded"),
        goal("b", "Delivery", "started"),  # left underway: the run ends with it
    ]
    agent = raw_agent(make_agent, tmp_path, plan)
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    first = goals.wait_summary(
        ROBOT, lambda s: s.completed == 1 and s.underway == 1, "the first run's goals"
    )
    pid = watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest).pid
    assert pid is not None
    os.killpg(pid, signal.SIGKILL)  # a crash: restarted by the policy, same request
    second = goals.wait_summary(
        ROBOT, lambda s: s.completed == 2 and s.run != first.run, "the second run's goals"
    )
    assert second.since == first.since and second.digest == digest
    assert second.stale == 1 and second.underway == 1  # b of the first run, b of the second
    records = goals.wait_records(ROBOT, 3)
    assert {(r.goal, r.outcome) for r in records if r.run == first.run} == {
        ("a", OutcomeState.SUCCEEDED),
        ("b", OutcomeState.STALE),
    }

    new_digest = launch(mosquitto, variant=1)
    third = goals.wait_summary(
        ROBOT, lambda s: s.digest == new_digest and s.completed == 1, "counts of the new request"
    )
    assert third.failed == third.stale == 0 and third.since is not None
    assert first.since is not None and third.since > first.since
    agent.note_brain(watch.wait_state(ROBOT, AgentState.RUNNING, digest=new_digest).pid)


GARBAGE = [
    {"send": "not json at all"},
    {"send": "{"},
    {"send": "[1, 2, 3]"},
    {"send": '{"type": "goal"}'},
    {"send": '{"type": "goal", "id": "x", "task": "T", "state": "started", "extra": 1}'},
    {"send": '{"type": "vitals", "values": {"a": NaN}}'},
    {"send": '{"type": "ready", "type": "hello"}'},
    {"send": '{"type": "goal", "id": "bad id with spaces", "task": "T", "state": "started"}'},
    {"send": "[" * 5000},
    {"send_hex": "fffe7b7d"},
    {"send": "x" * 10_000},  # over MAX_LINE_BYTES
]


def test_a_lying_flooding_garbage_writing_brain_is_bounded_and_the_agent_goes_on(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    lie = "sha256:" + "f" * 64
    escapes = "\x1b[31mred\x1b[0m\u202eevil\n" + "long " * 200
    plan = [
        {"send": json.dumps({"type": "hello", "digest": lie})},
        {"send": READY},
        *GARBAGE,
        goal("e", "Delivery", "started", note=escapes[:800]),
        goal("e", "Delivery", "failed", code="E_BLOCKED", message=escapes[:800]),
        line(type="event", severity="critical", message=escapes[:800]),
        line(type="vitals", values={"status": escapes[:200]}),
        {"flood": json.dumps({"type": "vitals", "values": {"n": 1}}), "count": 50_000},
        {"connect": 10},  # the brain holds one already; 4 at most
        {"sleep": 6.0},  # the bucket refills
        goal("after", "Delivery", "started"),
        goal("after", "Delivery", "succeeded"),
    ]
    agent = raw_agent(make_agent, tmp_path, plan)
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    agent.note_brain(watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest).pid)

    summary = goals.wait_summary(ROBOT, lambda s: s.completed == 1, "the goal after the flood")
    assert summary.failed == 1 and summary.digest == digest
    # Every garbage line, the flood beyond its bucket and the extra connections: counted.
    assert summary.dropped >= len(GARBAGE) + 7
    lied = [e for e in summary.events if "says it runs" in e.message]
    assert lied and lie[:19] in lied[0].message and lied[0].severity.value == "warning"
    failed = next(r for r in summary.recent if r.outcome is OutcomeState.FAILED)
    critical = next(e for e in summary.events if e.severity.value == "critical")
    assert summary.current is None
    for text in (failed.message or "", critical.message, str(summary.vitals["status"])):
        assert len(text) <= MAX_TEXT
        assert "\x1b" not in text and "\u202e" not in text and "\n" not in text
        assert text.startswith("\\x1b[31mred")
    records = goals.wait_records(ROBOT, 2)
    assert {r.digest for r in records} == {digest}, "records carry the agent's digest"
    assert [r.goal for r in records] == ["e", "after"]
    # The loop was never held: the agent takes a new request as ever.
    new_digest = launch(mosquitto, variant=1)
    agent.note_brain(watch.wait_state(ROBOT, AgentState.RUNNING, digest=new_digest).pid)
    assert agent.proc is not None and agent.proc.poll() is None


def test_a_flooding_brain_does_not_hold_another_robots_agent_in_the_same_process(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    flood = json.dumps({"type": "goal", "id": "f", "task": "Flood", "state": "progress"})
    flooder = raw_agent(
        make_agent,
        tmp_path,
        [{"send": HELLO}, {"send": READY}, *[{"flood": flood, "count": 20_000}] * 20],
        name="flooder",
        robot_id="tb3-02",
    )
    quiet = raw_agent(
        make_agent,
        tmp_path,
        [
            {"send": HELLO},
            {"send": READY},
            {"sleep": 1.0},
            goal("q", "Delivery", "started"),
            goal("q", "Delivery", "succeeded"),
        ],
        name="quiet",
    )
    flooder.start(quiet)
    watch.wait_state("tb3-02", AgentState.IDLE, agent=flooder)
    watch.wait_state(ROBOT, AgentState.IDLE, agent=flooder)
    launch(mosquitto, robot="tb3-02")
    flooding = goals.wait_summary("tb3-02", lambda s: s.dropped > 0, "the flood refused")
    assert flooding.underway == 1
    digest = launch(mosquitto)
    summary = goals.wait_summary(ROBOT, lambda s: s.completed == 1, "the quiet robot's goal")
    assert summary.dropped == 0 and summary.digest == digest
    for robot in (ROBOT, "tb3-02"):
        flooder.note_brain(watch.wait_state(robot, AgentState.RUNNING, agent=flooder).pid)


def test_a_stale_socket_file_is_replaced(
    mosquitto: Mosquitto,
    watch: FleetWatch,
    goals: GoalsWatch,
    make_agent: AgentFactory,
    tmp_path: Path,
) -> None:
    agent = raw_agent(
        make_agent, tmp_path, [{"send": HELLO}, {"send": READY}, goal("z", "T", "started")]
    )
    agent.workdir.mkdir(parents=True)
    (agent.workdir / "brain.sock").write_text("left over\n", encoding="utf-8")
    agent.start()
    watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
    digest = launch(mosquitto)
    agent.note_brain(watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent, digest=digest).pid)
    goals.wait_summary(ROBOT, lambda s: s.underway == 1, "the goal through the new socket")
    mode = (agent.workdir / "brain.sock").lstat().st_mode
    assert stat.S_ISSOCK(mode) and stat.S_IMODE(mode) == 0o600
    wait_for(lambda: "raw brain up" in agent.brain_log(), "the brain's output")


def test_records_wait_while_the_broker_is_away(tmp_path: Path) -> None:
    """Ended goals while the agent has no broker reach the reader once it is back: the agent
    keeps them (the reader's persistent session keeps them at the broker's side)."""
    broker = Mosquitto(tmp_path / "broker", persistence=True)
    broker.start()
    plan = [
        {"send": HELLO},
        {"send": READY},
        {"sleep": 3.0},  # the broker is taken away meanwhile
        *[goal(f"w{i}", "Delivery", state) for i in range(3) for state in ("started", "failed")],
        {"print": "goals sent"},
    ]
    plan_path = tmp_path / "plan.json"
    plan_path.write_text(json.dumps(plan), encoding="utf-8")
    command = [sys.executable, str(RAW_BRAIN), str(plan_path), "{launch_request}"]
    agent = AgentProc(tmp_path / "agent", broker.url, command=command)
    reader = paho.Client(
        CallbackAPIVersion.VERSION2, client_id="outcome-reader", clean_session=False
    )
    got: list[OutcomeRecord] = []
    reader.on_connect = lambda c, *a: c.subscribe(Topics().all_goal_outcomes, qos=1)
    reader.on_message = lambda c, u, m: got.append(OutcomeRecord.model_validate_json(m.payload))
    reader.reconnect_delay_set(min_delay=1, max_delay=2)
    watch = FleetWatch(broker.url)
    try:
        reader.connect(broker.host, broker.port)
        reader.loop_start()
        agent.start()
        watch.wait_state(ROBOT, AgentState.IDLE, agent=agent)
        publish(broker.url, LAUNCH, make_request().payload())
        agent.note_brain(watch.wait_state(ROBOT, AgentState.RUNNING, agent=agent).pid)
        broker.stop()
        wait_for(lambda: "goals sent" in agent.brain_log(), "the goals sent without a broker")
        broker.start()
        wait_for(lambda: len(got) >= 3, "the records kept while the broker was away")
        assert [(r.goal, r.outcome) for r in got[:3]] == [
            (f"w{i}", OutcomeState.FAILED) for i in range(3)
        ]
    finally:
        reader.disconnect()
        reader.loop_stop()
        watch.close()
        agent.cleanup()
        broker.kill()
