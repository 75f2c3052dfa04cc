"""What robots achieve, read from a real Mosquitto: retained goals summaries as agents publish them
become `robotconf status`'s goals column and `--json` `goals`/`vitals`, and the UI's rows (read one
robot at a time as progress moves) and its pages. No agent here: the test plays the robots'."""

from __future__ import annotations

import json
import subprocess
from typing import Any

from robotconf.contract.goals import CurrentGoal
from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import Topics
from robotconf.workstation.fleet_status import DesiredCache, fleet_status
from robotconf.workstation.ui.state import LiveFleet
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.goals_summaries import AT, REV1, publish_summary, summary
from tests.support.mosquitto import Mosquitto
from tests.support.ui import UiProc
from tests.support.watch import wait_for

HOSTILE = "<b>bold</b>\x1b[2J\u202e"


def status(lab: GitLab, url: str, *extra: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("status", "--repo", str(lab.root), "--broker", url, *extra),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def rows(lab: GitLab, url: str) -> dict[str, dict[str, Any]]:
    found = json.loads(status(lab, url, "--json").stdout)
    return {r["robot_id"]: r for r in found["robots"]}


def test_status_shows_goals_from_the_retained_summaries(lab: GitLab, mosquitto: Mosquitto) -> None:
    url = mosquitto.url
    assert "GOALS" not in status(lab, url).stdout  # no agent publishes goals: the table as before
    publish_summary(url, "tb3-01", summary("tb3-01", events=[], last=None, recent=[]))
    publish_summary(url, "tb3-02", summary("tb3-02", reporting=False, completed=0, failed=0))
    publish_summary(url, "tb3-03", b"\x00garbage")
    publish_summary(url, "tb3-04", summary("tb3-01"))  # another robot's, on tb3-04's topic
    publish_summary(url, "tb3-05", summary("tb3-05", vitals={"mood": HOSTILE}, failed=7))

    found = rows(lab, url)
    goals = found["tb3-01"]["goals"]
    assert {k: goals[k] for k in ("completed", "failed", "canceled", "underway", "stale")} == {
        "completed": 3,
        "failed": 1,
        "canceled": 0,
        "underway": 1,
        "stale": 0,
    }
    assert goals["current"]["goal"] == "g-5" and goals["current"]["fraction"] == 0.4
    assert goals["last"] is None and goals["revision"] == REV1
    assert found["tb3-01"]["vitals"]["battery"] == 0.82
    # A brain that does not report, garbage, another robot's summary: unknown or error, never
    # failed; no summary at all: unknown.
    assert (found["tb3-02"]["goals"], found["tb3-02"]["goals_state"]) == (None, "unknown")
    for robot_id in ("tb3-03", "tb3-04"):
        assert (found[robot_id]["goals"], found[robot_id]["goals_state"]) == (None, "error")
    assert (found["tb3-07"]["goals"], found["tb3-07"]["goals_state"]) == (None, "unknown")
    assert found["tb3-05"]["vitals"]["mood"] == HOSTILE  # JSON escapes it as JSON does

    text = status(lab, url).stdout
    lines = {line.split()[0]: line for line in text.splitlines() if line.startswith("tb3-0")}
    assert "GOALS" in text and "done/failed" in text
    assert " 3/1 " in lines["tb3-01"] and " 3/7 " in lines["tb3-05"]
    assert " unknown " in lines["tb3-02"] + " " and " error " in lines["tb3-03"] + " "
    assert "\x1b" not in text and "\u202e" not in text
    assert "unreadable retained payloads skipped: 2 goals" in text

    publish_summary(url, "tb3-01", b"")  # its agent clears it: unknown again
    assert rows(lab, url)["tb3-01"]["goals"] is None


def test_the_ui_follows_a_robot_s_progress_and_its_pages_show_it(
    lab: GitLab, mosquitto: Mosquitto
) -> None:
    topics = Topics()
    lab.commit("the lab")
    live = LiveFleet(Connection(mosquitto.url), topics.prefix, lab.root)
    live.start()
    try:
        wait_for(lambda: live.snapshot.fleet, "the first state")
        for step in range(1, 6):
            current = CurrentGoal(
                goal="g-5", task="Delivery", started_at=AT, updated_at=AT + step, fraction=step / 5
            )
            publish_summary(mosquitto.url, "tb3-01", summary("tb3-01", current=current))

            def moved(fraction: float = step / 5) -> bool | None:
                row = live.snapshot.row("tb3-01")
                s = row.goals.summary if row is not None else None
                return (
                    s is not None and s.current is not None and s.current.fraction == fraction
                ) or None

            wait_for(moved, f"the UI's row of tb3-01 at {step / 5:.0%}")
        whole = fleet_status(live.view.snapshot(), topics, DesiredCache(lab.root, None))
        shown = live.snapshot.fleet
        assert shown is not None and shown.rows == whole.rows
    finally:
        live.stop()

    ui = UiProc(lab.root, mosquitto.url, lab.root.parent / "ui.log")
    try:
        page = ui.wait_page("/robots/tb3-01", lambda b: "<progress" in b, "the progress bar")
        assert '<progress max="1" value="1.0000"' in page and "NAV2_TIMEOUT" in page
        fleet = ui.wait_page("/", lambda b: "data-rates" in b, "the success rates")
        assert f'data-revision="{REV1}" data-rate="75%"' in fleet
    finally:
        ui.stop()
