"""Rollouts verified by what the robots achieve, on real processes: stand-in brains that fail
their goals on the new revision stop it at the canary and roll it back; good ones pass wave by
wave; too few goals pause the rollout until an operator resumes or aborts it from the desk.
Every verdict is a git note on the revision."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

from robotconf.contract.launch import RolloutAction
from robotconf.contract.notes import NOTES_REF, read_notes
from robotconf.contract.wire import ReconcilerStatus
from tests.integration.agent.test_ui_operator import FORM, TOKEN, UiProc
from tests.integration.reconciler.conftest import Fleet, fleet_on
from tests.integration.reconciler.test_rollout import (
    CANARY,
    complete,
    launched,
    rename_all,
    running_digest,
    with_policy,
)
from tests.integration.reconciler.test_rollout_deaths import (
    kill_reconciler,
    never_rolled_back,
    rolled_back,
)
from tests.integration.reconciler.test_up import start_up
from tests.support.agents import publish
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

SCENARIO = "configs/scenarios/delivery-gazebo.yaml"  # tb3-01 (the canary) and tb3-06 run it
KNOWLEDGE = 'knowledge: {TARGET: {GOAL_ID: "2"}}'


def policy(verify: str) -> str:
    return (
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        "  healthy_after: 0.5\n  max_failures: 0\n  wave_timeout: 60\n  on_failure: rollback\n"
        f"  verify: {{{verify}}}\n"
    )


def brains(fleet: Fleet, rate: float, message: str) -> str:
    """A commit whose stand-in brains on the canary's scenario end a goal every 0.2 s, and
    succeed at `rate`."""
    fleet.lab.replace(
        SCENARIO,
        KNOWLEDGE,
        'knowledge: {TARGET: {GOAL_ID: "2"}, STANDIN_GOAL_SECONDS: 0.2, '
        f"STANDIN_SUCCESS_RATE: {rate}}}",
    )
    return fleet.lab.commit(message)


def notes(fleet: Fleet, revision: str) -> list[dict[str, object]]:
    done = subprocess.run(
        ["git", "-C", str(fleet.lab.root), "notes", f"--ref={NOTES_REF}", "show", revision],
        capture_output=True,
        text=True,
        check=False,
    )
    return [n.model_dump() for n in read_notes(done.stdout, revision)]


def paused_in(status: ReconcilerStatus, revision: str, wave: str) -> bool:
    rollout = status.rollout
    return (
        rollout is not None
        and rollout.revision == revision
        and rollout.state == "Paused"
        and rollout.wave_name == wave
    )


def desk(fleet: Fleet, *args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("rollout", *args, "--broker", fleet.broker.url, "--as", "ada"),
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def test_brains_that_fail_their_goals_are_stopped_at_the_canary(fleet: Fleet) -> None:
    stable = with_policy(fleet, policy("min_goals: 5, success_rate: 0.8, timeout: 120"))
    before = fleet.requests(stable)
    fleet.watch.live_launches.clear()
    bad = brains(fleet, 0.0, "brains that fail every goal")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, bad), "the rollback")
    assert status.rollout is not None and status.rollout.verification is not None
    verification = status.rollout.verification
    assert verification.verdict == "Failed" and verification.failed >= 2
    assert "verification of wave 'canary' failed" in status.message
    # Alive all along (healthy by the old measure), rolled back for what it achieved.
    assert status.rollout.failed == []
    wait_for(lambda: running_digest(fleet, CANARY, before[CANARY]), "the canary rolled back")
    assert launched(fleet, "tb3-06") == []  # the next wave never got it
    kept = notes(fleet, bad)
    assert [(n["kind"], n["wave_name"], n["verdict"]) for n in kept] == [
        ("verification", "canary", "Failed")
    ]
    # `robotconf status` shows the evidence; `git log --notes=robotconf` the verdict.
    report = json.loads(fleet.status_cli("--json").stdout)
    assert report["reconciler"]["rollout"]["verification"]["verdict"] == "Failed"
    log = subprocess.run(
        ["git", "-C", str(fleet.lab.root), "log", "-1", "--notes=robotconf", bad],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert '"verdict": "Failed"' in log


def test_brains_that_do_their_work_pass_every_wave_on_evidence(fleet: Fleet) -> None:
    with_policy(fleet, policy("min_goals: 3, success_rate: 0.9, timeout: 120"))
    good = brains(fleet, 1.0, "faster brains")
    fleet.watch.wait_reconciler(lambda s: complete(s, good), "the rollout complete")
    fleet.watch.wait_running(fleet.requests(good))
    kept = notes(fleet, good)
    assert [(n["wave_name"], n["verdict"]) for n in kept] == [
        ("canary", "Successful"),
        ("all", "Successful"),
    ]
    assert all(isinstance(n["goals"], int) and n["goals"] >= 3 for n in kept)


def test_too_few_goals_pause_it_until_an_operator_resumes_or_aborts(fleet: Fleet) -> None:
    stable = with_policy(fleet, policy("min_goals: 100000, timeout: 3, inconclusive: pause"))
    head = rename_all(fleet, "v2")
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "canary"), "the canary paused")
    status = fleet.watch.reconciler()
    assert status is not None and status.rollout is not None
    assert "robotconf rollout resume" in status.rollout.message
    assert status.rollout.verification is not None
    assert status.rollout.verification.verdict == "Inconclusive"
    # Nothing to abort of another revision; the resume is carried out and confirmed.
    refused = desk(fleet, "resume", "--revision", stable[:12])
    assert refused.returncode == 1 and "not" in refused.stderr
    resumed = desk(fleet, "resume")
    assert resumed.returncode == 0, resumed.stderr
    assert "resumed by ada" in resumed.stdout
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "all"), "the last wave paused")
    assert desk(fleet, "abort").returncode == 0
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the rollback")
    assert "aborted by ada" in status.message
    fleet.watch.wait_running(fleet.requests(stable))
    kinds = [(n["kind"], n.get("wave_name"), n.get("by")) for n in notes(fleet, head)]
    assert ("resume", "canary", "ada") in kinds and ("abort", "all", "ada") in kinds
    # Aborted, there is nothing left to resume.
    again = desk(fleet, "resume")
    assert again.returncode == 1 and "RolledBack" in again.stderr


def test_an_operator_resumes_from_the_browser_view_and_a_viewer_cannot(
    fleet: Fleet, tmp_path: Path
) -> None:
    with_policy(fleet, policy("min_goals: 100000, timeout: 3, inconclusive: pause"))
    head = rename_all(fleet, "v2")
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "canary"), "the canary paused")
    (tmp_path / "ui").mkdir()
    ui = UiProc(tmp_path / "ui", fleet.broker, "--prefix", "robotconf")
    try:
        page = ui.ask("GET", "/rollout/resume")
        assert page.code == 401  # a viewer may look, not decide
        assert ui.ask("POST", "/rollout/resume", "csrf=x", Content_Type=FORM).code == 401
        bearer = {"Authorization": f"Bearer {TOKEN}"}
        confirm = ui.ask("GET", "/rollout/resume", **bearer)
        assert confirm.code == 200 and "data-confirm-rollout" in confirm.body
        done = ui.ask("POST", "/rollout/resume", b"", **bearer)
        assert done.code == 303, done.body
        fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "all"), "the next wave paused")
        outcome = wait_for(
            lambda: (
                'data-rollout-decision="confirmed"'
                in (body := ui.ask("GET", "/rollout/abort", **bearer).body)
                and body
            ),
            "the UI shows the reconciler's answer",
        )
        assert "resumed by ui.bearer" in outcome
    finally:
        ui.close()
        assert "Traceback" not in ui.stderr(), ui.stderr()
    kinds = [(n["kind"], n.get("by")) for n in notes(fleet, head)]
    assert ("resume", "ui.bearer") in kinds


# ------------------------------------------------------------------ a reconciler that dies


def test_a_reconciler_killed_while_evidence_is_gathered_reaches_the_same_verdicts(
    fleet: Fleet,
) -> None:
    stable = with_policy(fleet, policy("min_goals: 15, success_rate: 0.9, timeout: 120"))
    fleet.watch.live_launches.clear()
    good = brains(fleet, 1.0, "faster brains")
    new = fleet.requests(good)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary on it")
    kill_reconciler(fleet)  # its goals keep coming, queued for the ledger's session
    time.sleep(2)
    fleet.start_reconciler("--interval", "5")
    fleet.watch.wait_reconciler(lambda s: complete(s, good), "the rollout complete")
    never_rolled_back(fleet, fleet.requests(stable))
    kept = notes(fleet, good)
    assert [(n["wave_name"], n["verdict"]) for n in kept] == [
        ("canary", "Successful"),
        ("all", "Successful"),
    ]


def test_brains_failing_while_the_reconciler_is_down_are_judged_when_it_is_back(
    fleet: Fleet,
) -> None:
    with_policy(fleet, policy("min_goals: 10, success_rate: 0.8, timeout: 120"))
    bad = brains(fleet, 0.0, "brains that fail every goal")
    new = fleet.requests(bad)
    wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary on it")
    kill_reconciler(fleet)
    time.sleep(2)  # ten failed goals, reported while nobody reads them
    fleet.start_reconciler("--interval", "5")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, bad), "the rollback")
    assert status.rollout is not None and status.rollout.verification is not None
    assert status.rollout.verification.failed >= 3


def test_a_paused_rollout_stays_paused_across_a_restart(fleet: Fleet) -> None:
    with_policy(fleet, policy("min_goals: 100000, timeout: 3, inconclusive: pause"))
    fleet.watch.live_launches.clear()
    head = rename_all(fleet, "v2")
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "canary"), "the canary paused")
    kill_reconciler(fleet)
    fleet.start_reconciler("--interval", "5")
    time.sleep(3)  # a few steps of the new reconciler
    status = fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "canary"), "still paused")
    assert status.rollout is not None and status.rollout.verification is not None
    assert status.rollout.verification.verdict == "Inconclusive"
    assert launched(fleet, "tb3-06") == []
    assert desk(fleet, "resume").returncode == 0
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "all"), "the next wave")


# ------------------------------------------------------------------ stages: sim, then real

REAL = ["tb3-04", "tb3-07"]
STAGES = (
    "rollout:\n  waves: [{name: all}]\n  healthy_after: 0.5\n  max_failures: 0\n"
    "  wave_timeout: 60\n  on_failure: rollback\n"
    "  verify: {min_goals: 3, success_rate: 0.8, timeout: 120}\n"
    "stages:\n  - {name: sim, environments: [Gazebo], soak: {goals: 6}}\n"
    "  - {name: real, environments: [Real]}\n"
)


def staged(fleet: Fleet, rate: float, suffix: str) -> str:
    """A commit that changes every robot's request, its delivery brains succeeding at `rate`."""
    rename_all(fleet, suffix)
    return brains(fleet, rate, f"brains at {rate} ({suffix})")


def test_a_revision_whose_brains_fail_is_stopped_in_sim_and_never_reaches_the_real_robots(
    fleet: Fleet,
) -> None:
    stable = with_policy(fleet, STAGES)
    fleet.watch.live_launches.clear()
    bad = staged(fleet, 0.0, "v2")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, bad), "the rollback in sim")
    assert status.rollout is not None
    assert [(s.name, s.state) for s in status.rollout.stages] == [
        ("sim", "failed"),
        ("real", "waiting"),
    ]
    assert all(launched(fleet, robot) == [] for robot in REAL)  # never sent anything
    fleet.watch.wait_running(fleet.requests(stable))
    assert [(n["stage"], n["verdict"]) for n in notes(fleet, bad)] == [("sim", "Failed")]


def test_a_good_revision_is_verified_and_soaked_in_sim_then_reaches_the_real_robots(
    fleet: Fleet,
) -> None:
    with_policy(fleet, STAGES)
    good = staged(fleet, 1.0, "v2")
    status = fleet.watch.wait_reconciler(lambda s: complete(s, good), "the rollout complete")
    assert status.rollout is not None
    assert [(s.name, s.state, s.verified_revision) for s in status.rollout.stages] == [
        ("sim", "verified", good),
        ("real", "verified", good),
    ]
    fleet.watch.wait_running(fleet.requests(good))
    kept = [(n["wave_name"], n["verdict"]) for n in notes(fleet, good)]
    assert kept == [
        ("sim/all", "Successful"),
        ("sim", "Successful"),  # the soak: 6 goals of the whole stage after its last wave
        ("real/all", "Successful"),
        ("real", "Successful"),
    ]
    soak = next(n for n in notes(fleet, good) if n["wave_name"] == "sim")
    assert isinstance(soak["goals"], int) and soak["goals"] >= 6


def test_a_revision_failing_on_the_real_robots_rolls_back_only_the_real_stage(
    fleet: Fleet,
) -> None:
    stable = with_policy(fleet, STAGES)
    patrol = "configs/scenarios/patrol-real.yaml"
    fleet.lab.write(patrol, fleet.lab.read(patrol) + "knowledge: {STANDIN_CRASH: 3}\n")
    head = staged(fleet, 1.0, "v2")  # good in sim; the real robots' brains crash on it
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, head), "the real rollback")
    assert status.rollout is not None
    assert [(s.name, s.state, s.verified_revision) for s in status.rollout.stages] == [
        ("sim", "verified", head),
        ("real", "failed", stable),
    ]
    assert "stage 'sim' keeps" in status.rollout.message
    # Sim keeps the head, verified there; the real robots have the stable revision back.
    wanted = {r: q for r, q in fleet.requests(head).items() if r not in REAL}
    wanted.update({r: q for r, q in fleet.requests(stable).items() if r in REAL})
    fleet.watch.wait_running(wanted)
    # The next commit fails in sim: its sim robots go back to the head, verified for them,
    # not to the older stable revision; the real robots keep the stable one throughout.
    fleet.lab.replace(SCENARIO, "STANDIN_SUCCESS_RATE: 1.0", "STANDIN_SUCCESS_RATE: 0.0")
    worse = fleet.lab.commit("delivery brains that fail (v3)")
    status = fleet.watch.wait_reconciler(lambda s: rolled_back(s, worse), "the sim rollback")
    assert status.rollout is not None
    assert [(s.state, s.verified_revision) for s in status.rollout.stages] == [
        ("failed", head),
        ("waiting", stable),
    ]
    fleet.watch.wait_running(wanted)


def test_an_operator_promotes_a_revision_to_the_real_robots_by_hand(fleet: Fleet) -> None:
    with_policy(fleet, STAGES.replace("min_goals: 3", "min_goals: 100000"))
    head = staged(fleet, 1.0, "v2")
    fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.revision == head, "the rollout under way"
    )
    refused = desk_promote(fleet, head[:10], "moon")
    assert refused.returncode == 1 and "no stage 'moon'" in refused.stderr
    done = desk_promote(fleet, head[:10], "real")
    assert done.returncode == 0, done.stderr
    assert "promoted to stage 'real' by ada" in done.stdout
    status = fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.stage == "real", "the real stage"
    )
    assert status.rollout is not None and status.rollout.stages[0].state == "verified"
    fleet.watch.wait_running({r: q for r, q in fleet.requests(head).items() if r in REAL})
    assert ("promote", "real", "ada") in [
        (n["kind"], n.get("stage"), n.get("by")) for n in notes(fleet, head)
    ]


def desk_promote(fleet: Fleet, revision: str, stage: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv(
            "promote", revision, "--to", stage, "--broker", fleet.broker.url, "--as", "ada"
        ),
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def test_a_reconciler_killed_during_a_stages_soak_promotes_nothing_unverified(
    fleet: Fleet,
) -> None:
    stable = with_policy(fleet, STAGES.replace("soak: {goals: 6}", "soak: {goals: 60}"))
    fleet.watch.live_launches.clear()
    good = staged(fleet, 1.0, "v2")
    fleet.watch.wait_reconciler(
        lambda s: s.rollout is not None and s.rollout.wave_name == "sim", "the sim gate's soak"
    )
    kill_reconciler(fleet)
    time.sleep(2)  # goals keep coming, queued for the ledger
    assert all(launched(fleet, robot) == [] for robot in REAL)
    fleet.start_reconciler("--interval", "5")
    status = fleet.watch.wait_reconciler(lambda s: complete(s, good), "the rollout complete")
    assert status.rollout is not None
    assert [s.state for s in status.rollout.stages] == ["verified", "verified"]
    never_rolled_back(fleet, fleet.requests(stable))
    gates = [n for n in notes(fleet, good) if n["wave_name"] == "sim"]
    assert len(gates) == 1 and gates[0]["verdict"] == "Successful"
    assert isinstance(gates[0]["goals"], int) and gates[0]["goals"] >= 60


# ------------------------------------------------------------------ `robotconf up`, the demo


def test_up_stops_a_revision_whose_brains_fail_in_sim(tmp_path: Path, mosquitto: Mosquitto) -> None:
    """The rollout guide's walk-through: the example fleet's rollout, verify and stages lines
    uncommented (quicker numbers for a demo), then a commit that lowers the delivery brains'
    success rate and renames every robot: stopped in sim, never on the real robots."""
    lab = GitLab(tmp_path / "lab")
    watch = FleetWatch(mosquitto.url)
    up = start_up(lab, tmp_path, "--broker", mosquitto.url)
    try:
        wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
        text = lab.read("configs/fleet.yaml")
        text = text.replace("\n# rollout:\n", "\nrollout:\n").replace("\n#   ", "\n  ")
        text = text.replace("\n# stages:", "\nstages:").replace("\n#  ", "\n  ")
        text = text.replace("healthy_after: 30", "healthy_after: 1")
        text = text.replace("min_goals: 20", "min_goals: 3").replace("timeout: 30m", "timeout: 2m")
        lab.write("configs/fleet.yaml", text)
        stable = lab.commit("roll out in stages, verified by goals")  # no request changes
        watch.wait_reconciler(lambda s: complete(s, stable), "the policy applied")
        before = lab.requests(stable)
        for name in ("Delivery bot", "Guide bot", "Bluetooth delivery bot", "Lab patrol"):
            lab.replace("configs/fleet.yaml", f"name: {name}", f"name: {name} v2")
        lab.replace(
            SCENARIO,
            KNOWLEDGE,
            'knowledge: {TARGET: {GOAL_ID: "2"}, STANDIN_GOAL_SECONDS: 0.2, '
            "STANDIN_SUCCESS_RATE: 0}",
        )
        bad = lab.commit("delivery brains that fail")
        status = watch.wait_reconciler(lambda s: rolled_back(s, bad), "stopped in sim")
        assert status.rollout is not None
        assert [(s.name, s.state) for s in status.rollout.stages] == [
            ("sim", "failed"),
            ("real", "waiting"),
        ]
        wait_for(lambda: "stages sim failed" in up.output(), "up to show it")
        assert lab.requests(bad)["tb3-04"].digest != before["tb3-04"].digest  # it would change
        watch.wait_running({r: q for r, q in before.items()})  # every robot on the stable
        # The real robots never ran the bad revision's request, not for a moment.
        bad_digest = lab.requests(bad)["tb3-04"].digest  # tb3-07 is not renamed: no change
        assert watch.history("tb3-04") and all(
            s.digest != bad_digest for s in watch.history("tb3-04")
        )
    finally:
        code = up.stop(signal.SIGINT, timeout=60)
        watch.close()
    assert code == 0, up.output()


def test_garbage_and_floods_on_the_requests_topic_stop_nothing(fleet: Fleet) -> None:
    """Whatever anyone allowed on the broker publishes to the reconciler's requests topic —
    garbage, deep JSON, a huge payload, forged, stale or replayed actions, a flood, a retained
    one — the reconciler counts it, answers what it can, and goes on; a good resume still
    works after it."""
    with_policy(fleet, policy("min_goals: 100000, timeout: 3, inconclusive: pause"))
    head = rename_all(fleet, "v2")
    paused = fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "canary"), "paused")
    assert paused.rollout is not None and paused.rollout.wave_started_at is not None
    topic = fleet.watch.topics.rollout_request
    real = RolloutAction(
        action="resume",
        revision=head,
        wave=0,
        wave_started_at=paused.rollout.wave_started_at,
        requested_by="mallory",
        issued_at=time.time(),
    )
    hostile = [
        b"",
        b"\xff\xfe not json",
        b"[" * 5000 + b"]" * 5000,
        b"x" * 300_000,
        json.dumps({"kind": "RolloutAction", "action": "resume"}).encode(),
        real.model_copy(update={"issued_at": time.time() - 3600}).payload(),  # stale
        real.model_copy(update={"wave": 1}).payload(),  # not the run that stands
        real.model_copy(update={"revision": "f" * 40}).payload(),
    ]
    for payload in hostile:
        publish(fleet.broker.url, topic, payload, retain=False)
    for _ in range(50):  # a flood: at most 16 wait for the loop, the rest are dropped
        publish(fleet.broker.url, topic, b"{}", retain=False)
    publish(fleet.broker.url, topic, b"{garbage", retain=True)  # a retained one comes at each start
    status = fleet.watch.wait_reconciler(
        lambda s: s.ignored_payloads.get("rollout-action", 0) >= 5, "the garbage counted"
    )
    assert status.rollout is not None and status.rollout.state == "Paused"  # nothing resumed
    answer = status.rollout.answer
    assert answer is None or not answer.accepted
    assert fleet.reconciler is not None and fleet.reconciler.alive()
    done = desk(fleet, "resume")
    assert done.returncode == 0, done.stderr
    fleet.watch.wait_reconciler(lambda s: paused_in(s, head, "all"), "resumed after all that")
    publish(fleet.broker.url, topic, b"", retain=True)  # clear the retained one


def test_a_broker_restarted_while_a_wave_is_verified_rolls_nothing_back(tmp_path: Path) -> None:
    """A persistent Mosquitto restarted while the canary's evidence is gathered: the robots'
    outcomes wait in their agents and in the ledger's session; the verdict is reached after,
    the rollout completes, and the canary is never rolled back for the restart."""
    broker = Mosquitto(tmp_path / "broker", persistence=True)
    (tmp_path / "broker").mkdir()
    broker.start()
    try:
        with fleet_on(tmp_path, broker) as fleet:
            stable = with_policy(fleet, policy("min_goals: 10, success_rate: 0.9, timeout: 120"))
            fleet.watch.live_launches.clear()
            good = brains(fleet, 1.0, "faster brains")
            new = fleet.requests(good)
            wait_for(lambda: running_digest(fleet, CANARY, new[CANARY]), "the canary on it")
            broker.restart()
            fleet.watch.wait_reconciler(lambda s: complete(s, good), "the rollout complete")
            never_rolled_back(fleet, fleet.requests(stable))
            kept = [(n["wave_name"], n["verdict"]) for n in notes(fleet, good)]
            assert kept == [("canary", "Successful"), ("all", "Successful")]
    finally:
        broker.kill()
