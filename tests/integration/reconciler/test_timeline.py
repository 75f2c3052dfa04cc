"""The fleet's timeline on real components: a reconciler on Mosquitto keeps a refused commit and
an applied one in its ledger, `robotconf events` (a real process) shows them and still does
after the reconciler is killed and started again; `robotconf ui` serves them at /timeline,
narrowed by robot and kind, every hostile query string a 400 or an empty list, never a 500."""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import quote

import pytest

from robotconf.readmodel.events import Event, Kind
from robotconf.readmodel.ledger import Ledger, ledger_path
from tests.integration.reconciler.conftest import Fleet
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.mosquitto import Mosquitto
from tests.support.ui import UiProc
from tests.support.watch import wait_for

SCENARIO = "configs/scenarios/delivery-gazebo.yaml"


def events_cli(state: Path, *args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("events", "--state-dir", str(state), *args),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def kept(state: Path) -> list[dict[str, Any]]:
    done = events_cli(state, "--json")
    if done.returncode not in (0, 1):  # the ledger not made yet: nothing kept yet
        return []
    found: list[dict[str, Any]] = json.loads(done.stdout)
    return found


def has(state: Path, kind: str, revision: str) -> bool:
    return any(e["event"] == kind and e["revision"] == revision for e in kept(state))


def test_refused_and_applied_commits_are_kept_across_a_reconciler_kill(
    fleet: Fleet, tmp_path: Path
) -> None:
    state = tmp_path / "state"
    assert fleet.reconciler is not None
    fleet.reconciler.stop()
    fleet.start_reconciler("--interval", "1", "--state-dir", str(state))
    original = fleet.lab.read(SCENARIO)
    fleet.lab.write(SCENARIO, original + "robots: [unclosed\n  : : -\n")
    bad = fleet.lab.commit("invalid YAML")
    wait_for(lambda: has(state, "commit_refused", bad), "the refused commit kept")
    fleet.lab.write(SCENARIO, original.replace("move_speed: 0.1", "move_speed: 0.12"))
    good = fleet.lab.commit("fixed, and slower")
    wait_for(lambda: has(state, "commit_applied", good), "the applied commit kept")
    assert has(state, "commit_recovered", good)

    assert fleet.reconciler is not None
    fleet.reconciler.kill()  # SIGKILL: no clean stop, only its Last Will
    fleet.start_reconciler("--interval", "1", "--state-dir", str(state))
    # A commit after the restart: once it is noted, the restarted reconciler has looked at
    # what it found, and did not note `good` applied a second time.
    fleet.lab.write(SCENARIO, original.replace("move_speed: 0.1", "move_speed: 0.11"))
    later = fleet.lab.commit("after the restart")
    wait_for(lambda: has(state, "commit_applied", later), "the next commit kept")
    found = kept(state)
    assert [e["event"] for e in found if e["revision"] == bad] == ["commit_refused"]
    assert [e["event"] for e in found if e["event"] == "commit_applied"][:2] == [
        "commit_applied",
        "commit_applied",
    ]
    applied = [e["revision"] for e in found if e["event"] == "commit_applied"]
    assert applied.index(later) < applied.index(good) and applied.count(good) == 1
    assert [e["at"] for e in found] == sorted((e["at"] for e in found), reverse=True)
    refused = next(e for e in found if e["event"] == "commit_refused")
    assert refused["robot"] is None and bad[:12] in refused["message"]

    # Narrowed, and as text: one line per event (time, kind, robot, message).
    only = events_cli(state, "--kind", "commit_refused", "--since", "1h")
    assert only.returncode == 0, only.stderr
    assert only.stdout.count("\n") == 1 and "  commit_refused  -  " in only.stdout
    nothing = events_cli(state, "--robot", "tb3-99")
    assert nothing.returncode == 1 and "no events match" in nothing.stdout


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (("--kind", "comit_refused"), "is not an event kind: one of commit_refused, "),
        (("--since", "yesterday"), "since: 'yesterday' is not a duration"),
        (("--robot", "tb3 01"), "is not a robot id"),
        (("--limit", "0"), "give 1 to"),
    ],
)
def test_a_bad_filter_is_one_line(tmp_path: Path, args: tuple[str, ...], said: str) -> None:
    done = events_cli(tmp_path, *args)
    assert done.returncode == 2 and said in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_no_ledger_is_one_line(tmp_path: Path) -> None:
    done = events_cli(tmp_path / "none")
    assert done.returncode == 2 and "no ledger at" in done.stderr


# ---------------------------------------------------------------------- the browser view

HOSTILE = '<script>alert(1)</script>"&\x1b[2J'


@pytest.fixture
def ui(lab: GitLab, mosquitto: Mosquitto, tmp_path: Path) -> Iterator[UiProc]:
    state = tmp_path / "state"
    now = time.time()
    with Ledger.open_or_start(ledger_path(state)) as ledger:
        ledger.add_events(
            [
                Event(Kind.COMMIT_REFUSED, "0a1b on main refused", now - 7200, "main", "0a" * 20),
                Event(
                    Kind.ROBOT_OFFLINE, f"tb3-01 is offline: {HOSTILE}", now - 200, robot="tb3-01"
                ),
                Event(
                    Kind.ROBOT_RESTARTED,
                    "tb3-02 restarted from the desk by alice",
                    now - 100,
                    robot="tb3-02",
                    by="alice",
                ),
                Event(Kind.ROBOT_DRIFTED, "x" * 100_000, now - 50, robot="tb3-03"),
            ]
        )
    proc = UiProc(lab.root, mosquitto.url, tmp_path / "ui.log", "--state-dir", str(state))
    try:
        yield proc
    finally:
        proc.stop()


def rows(page: str) -> list[str]:
    return [line.split('"')[1] for line in page.split("<tr data-event=")[1:]]


def test_the_timeline_page_newest_first_filtered_and_escaped(ui: UiProc) -> None:
    fleet_page = ui.get("/")
    assert fleet_page.code == 200 and '<a href="/timeline">Timeline</a>' in fleet_page.body
    page = ui.get("/timeline")
    assert page.code == 200, page.body
    assert rows(page.body) == [
        "robot_drifted",
        "robot_restarted",
        "robot_offline",
        "commit_refused",
    ]
    assert "<script>alert" not in page.body and "&lt;script&gt;alert(1)" in page.body
    assert "\x1b" not in page.body and len(page.body) < 20_000  # every field cut
    assert "by alice" in page.body and page.headers["Content-Security-Policy"]
    assert rows(ui.get("/timeline?robot=tb3-02").body) == ["robot_restarted"]
    assert rows(ui.get("/timeline?kind=commit_refused&robot=").body) == ["commit_refused"]
    assert rows(ui.get("/timeline?kind=robot_offline&robot=tb3-02").body) == []
    assert 'data-timeline="empty"' in ui.get("/timeline?robot=tb3-99").body
    recent = ["robot_drifted", "robot_restarted", "robot_offline"]
    assert rows(ui.get("/timeline?since=1h").body) == recent


@pytest.mark.parametrize(
    "query",
    [
        "kind=" + "x" * 900,
        "robot=" + quote("<img src=x>"),
        "robot=" + "r" * 5000,
        "since=" + "9" * 31,
        "since=-5m",
        "kind=%ff%fe",
        "robot=%00",
        "&".join(f"f{i}=1" for i in range(50)),
        "since=" + quote("1e999"),
        "a=" + "%" * 300,
    ],
)
def test_hostile_query_strings_are_refused_or_empty_never_a_500(ui: UiProc, query: str) -> None:
    answer = ui.get(f"/timeline?{query}")
    assert answer.code in (200, 400), (answer.code, answer.body[:300])
    if answer.code == 200:
        assert "<img src=x>" not in answer.body
    assert ui.get("/healthz").code == 200
