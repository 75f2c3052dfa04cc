"""Operators' decisions against a reconciler that dies, on real processes: the reconciler killed
between keeping an operator's resume or promotion as a git note on the revision and the step
that acts on it. Restarted, it reads the note and carries the decision out, once: the paused
wave run goes on, the promoted revision reaches its stage; nothing is promoted that was neither
verified nor promoted by hand, and no robot is rolled back for the restart."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from typing import Literal

import pytest

from robotconf.contract.launch import RolloutAction
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import ReconcilerStatus, RolloutStatus
from robotconf.reconciler.notes_store import NotesStore
from robotconf.reconciler.operator_actions import Taken, judge_action
from tests.integration.reconciler.conftest import Fleet
from tests.integration.reconciler.test_alerts import Receiver
from tests.integration.reconciler.test_rollout import complete, launched, rename_all, with_policy
from tests.integration.reconciler.test_rollout_deaths import kill_reconciler, never_rolled_back
from tests.integration.reconciler.test_rollout_verify import (
    REAL,
    STAGES,
    desk,
    notes,
    paused_in,
    policy,
    staged,
)
from tests.support.fleet import robotconf_argv
from tests.support.watch import wait_for

PAUSE = "min_goals: 100000, timeout: 3, inconclusive: pause"  # every wave pauses, inconclusive
BY_HAND = STAGES.replace("min_goals: 3", "min_goals: 100000")  # sim is passed only by hand


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    made = Receiver()
    try:
        yield made
    finally:
        made.close()


def decided(
    rollout: RolloutStatus, action: Literal["resume", "promote"], stage: str | None = None
) -> VerdictNote:
    """The note the reconciler keeps when it takes ada's `action` on `rollout`: judge_action's."""
    assert rollout.wave_started_at is not None
    now = time.time()
    request = RolloutAction(
        action=action,
        revision=rollout.revision,
        wave=rollout.wave,
        wave_started_at=rollout.wave_started_at,
        requested_by="ada",
        issued_at=now,
        stage=stage,
    )
    found = judge_action(request.payload(), rollout, now, None)
    assert isinstance(found, Taken), found
    return found.note


def restart(fleet: Fleet, *extra: str) -> float:
    """The reconciler started again; when, to tell its statuses from the dead one's."""
    at = time.time()
    fleet.start_reconciler("--interval", "5", *extra)
    return at


def since(at: float, status: ReconcilerStatus) -> bool:
    return status.heartbeat is not None and status.heartbeat >= at


def kinds(fleet: Fleet, revision: str, kind: str) -> list[tuple[object, ...]]:
    return [
        (n.get("wave_name"), n.get("stage"), n.get("by"))
        for n in notes(fleet, revision)
        if n["kind"] == kind
    ]


# ------------------------------------------------------------------ a resume


def resumed_while_dead(fleet: Fleet, *extra: str) -> tuple[str, str]:
    """A rollout paused at the canary, the reconciler killed, ada's resume noted on the
    revision as the reconciler notes it, and the reconciler started again: (stable, head)."""
    stable = with_policy(fleet, policy(PAUSE))
    fleet.watch.live_launches.clear()
    head = rename_all(fleet, "v2")
    paused = fleet.watch.wait_reconciler(
        lambda s: paused_in(s, head, "canary"), "the canary paused"
    )
    assert paused.rollout is not None
    kill_reconciler(fleet)
    assert launched(fleet, "tb3-06") == []
    NotesStore(fleet.lab.root).append([decided(paused.rollout, "resume")])  # then it died
    restart(fleet, *extra)
    return stable, head


def test_a_resume_noted_while_the_reconciler_is_dead_goes_on_when_it_is_back(
    fleet: Fleet,
) -> None:
    stable, head = resumed_while_dead(fleet)
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "all"), "the next wave paused")
    # The canary's wave passed by ada's hand: its verdict says who.
    canary = [n for n in notes(fleet, head) if n.get("wave_name") == "canary"]
    assert [(n["kind"], n["verdict"], n["by"]) for n in canary] == [
        ("verification", "Inconclusive", None),  # the pause, before the death
        ("resume", None, "ada"),
        ("verification", "Inconclusive", "ada"),  # passed, by hand
    ]
    assert desk(fleet, "resume").returncode == 0
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(fleet.requests(head))
    never_rolled_back(fleet, fleet.requests(stable))
    assert kinds(fleet, head, "resume") == [("canary", None, "ada"), ("all", None, "ada")]


def test_a_resume_carried_out_across_a_restart_is_told(fleet: Fleet, receiver: Receiver) -> None:
    _, head = resumed_while_dead(fleet, "--notify", receiver.url)
    paused = wait_for(
        lambda: [
            e for e in receiver.events("rollout_paused", revision=head) if "'all'" in e["message"]
        ],
        "the next wave's pause told",
    )
    told = [(e["event"], e["message"]) for e in receiver.got()]
    assert receiver.events("rollout_resumed", revision=head), told  # told before the pause
    assert "by ada" in receiver.events("rollout_resumed", revision=head)[0]["message"]
    assert paused


def test_a_reconciler_killed_as_it_notes_a_desk_resume_goes_on_when_it_is_back(
    fleet: Fleet,
) -> None:
    stable = with_policy(fleet, policy(PAUSE))
    fleet.watch.live_launches.clear()
    head = rename_all(fleet, "v2")
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "canary"), "the canary paused")
    operator = subprocess.Popen(
        robotconf_argv(
            "rollout", "resume", "--broker", fleet.broker.url, "--as", "ada", "--wait", "10"
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not kinds(fleet, head, "resume"):
            assert time.monotonic() < deadline, "the resume never noted"
            time.sleep(0.02)
        kill_reconciler(fleet)  # the note kept; its step perhaps not taken
        restart(fleet)
        out, err = operator.communicate(timeout=90)
    finally:
        if operator.poll() is None:
            operator.kill()
            operator.wait()
    assert "Traceback" not in out + err, err  # it may say it got no answer: it had none
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "all"), "the next wave paused")
    assert desk(fleet, "resume").returncode == 0
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(fleet.requests(head))
    never_rolled_back(fleet, fleet.requests(stable))
    assert kinds(fleet, head, "resume") == [("canary", None, "ada"), ("all", None, "ada")]


# ------------------------------------------------------------------ a promotion


def test_a_promotion_noted_while_the_reconciler_is_dead_and_only_it_reaches_the_real_robots(
    fleet: Fleet,
) -> None:
    stable = with_policy(fleet, BY_HAND)
    fleet.watch.live_launches.clear()
    head = staged(fleet, 1.0, "v2")
    fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the rollout in sim"
    )
    # Killed and back with no decision: sim healthy but not verified, nothing goes to the real
    # robots.
    kill_reconciler(fleet)
    at = restart(fleet)
    back = fleet.watch.wait_reconciler(
        lambda s: (
            since(at, s)
            and s.rollout is not None
            and s.rollout.revision == head
            and s.rollout.wave_name == "sim/all"
            and bool(s.rollout.healthy)
            and not s.rollout.pending
        ),
        "the restarted reconciler: sim healthy, its evidence short",
    )
    assert back.rollout is not None and back.rollout.verification is not None
    assert back.rollout.verification.verdict is None  # gathering: not verified
    assert [s.state for s in back.rollout.stages][1:] == ["waiting"]
    assert back.rollout.stages[0].state != "verified"
    assert all(launched(fleet, robot) == [] for robot in REAL)
    kill_reconciler(fleet)
    assert all(launched(fleet, robot) == [] for robot in REAL)
    NotesStore(fleet.lab.root).append([decided(back.rollout, "promote", "real")])
    restart(fleet)
    status = fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.stage == "real", "the real stage"
    )
    assert status.rollout is not None and status.rollout.stages[0].state == "verified"
    fleet.watch.wait_running({r: q for r, q in fleet.requests(head).items() if r in REAL})
    never_rolled_back(fleet, fleet.requests(stable))
    assert kinds(fleet, head, "promote") == [(None, "real", "ada")]
