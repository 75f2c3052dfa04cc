"""What robots achieve, in a real browser: headless Chromium on `robotconf ui` of a real Mosquitto,
where the test publishes retained goals summaries as agents do. A robot's progress bar moves and
its outcomes arrive on the open page without a reload; robot-supplied text is text; the fleet
page shows each robot's goals and the success rate per scenario and revision.

DOM contract (docs/architecture.md): `[data-box="goals"][data-goals]`, `[data-current-goal]` with
its `<progress>`, `table[data-outcomes] tr[data-outcome]`, `[data-vital]`, `[data-brain-events]
li[data-severity]`; on the fleet page `td[data-goals]` and `table[data-rates]
tr[data-scenario][data-revision][data-rate]`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from robotconf.contract.goals import BrainEvent, CurrentGoal, OutcomeRecord, OutcomeState, Severity
from robotconf.readmodel.ledger import Ledger, ledger_path
from tests.integration.ui.test_browser import (  # noqa: F401 (pages_without_errors: autouse)
    expect_ms,
    open_page,
    pages_without_errors,
)
from tests.support.browser import screenshot_folders
from tests.support.fleet import GitLab
from tests.support.goals_summaries import AT, REV1, ended, publish_summary, summary
from tests.support.mosquitto import Mosquitto
from tests.support.ui import UiProc

if TYPE_CHECKING:
    from playwright.sync_api import Browser

ROBOT = "tb3-01"
HOSTILE = '<img src=x onerror="window.pwned=1">'


@pytest.fixture
def ui(tmp_path: Path, mosquitto: Mosquitto) -> Iterator[tuple[UiProc, str]]:
    lab = GitLab(tmp_path / "lab")
    lab.commit("the lab")
    keep_outcomes(tmp_path / "state")
    proc = UiProc(
        lab.root, mosquitto.url, tmp_path / "ui.log", "--prefix", "robotconf",
        "--state-dir", str(tmp_path / "state"),
    )  # fmt: skip
    try:
        yield proc, mosquitto.url
    finally:
        proc.stop()


def keep_outcomes(state_dir: Path) -> None:
    """The reconciler's ledger, as its feed writes it: REV1's Delivery goals, 7 of 10 succeeded."""
    records = [
        OutcomeRecord(
            robot_id="tb3-01",
            revision=REV1,
            digest=None,
            scenario="delivery-gazebo",
            run="run-1",
            seq=seq,
            goal=f"g{seq}",
            task="Delivery",
            outcome=OutcomeState.SUCCEEDED if seq < 7 else OutcomeState.FAILED,
            code=None if seq < 7 else "NAV2_TIMEOUT",
            ended_at=AT + seq,
        )
        for seq in range(10)
    ]
    with Ledger.open_or_start(ledger_path(state_dir)) as ledger:
        ledger.add(records, received_at=AT + 10)


def underway(fraction: float | None, note: str | None = None) -> CurrentGoal:
    return CurrentGoal(
        goal="g-5", task="Delivery", started_at=AT, updated_at=AT + 1, fraction=fraction, note=note
    )


def test_the_progress_bar_moves_and_outcomes_arrive_on_an_open_page(
    ui: tuple[UiProc, str], browser: Browser, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    proc, url = ui
    publish_summary(url, ROBOT, summary(ROBOT, current=underway(0.2)))
    page = open_page(browser)
    page.goto(f"http://127.0.0.1:{proc.port}/robots/{ROBOT}")
    bar = page.locator("[data-current-goal] progress")
    expect(bar).to_have_attribute("value", "0.2000", **expect_ms())
    expect(page.locator("[data-current-goal] [data-percent]")).to_have_text("20%")
    page.evaluate("window.notReloaded = true")

    # Progress, then the goal's end: the open page follows, the bar's value is the element's.
    publish_summary(url, ROBOT, summary(ROBOT, current=underway(0.65, note="at the ball")))
    expect(bar).to_have_attribute("value", "0.6500", **expect_ms())
    assert page.eval_on_selector("[data-current-goal] progress", "p => p.position") == 0.65
    expect(page.locator("[data-current-goal]")).to_contain_text("at the ball")
    for folder in screenshot_folders(tmp_path):  # the docs' picture of a robot's goals
        page.locator('[data-box="goals"]').screenshot(path=str(folder / "ui-goals.png"))

    failed = ended("g-5", OutcomeState.FAILED, "E_BLOCKED", HOSTILE, at=AT + 30)
    done = summary(
        ROBOT,
        current=None,
        completed=3,
        failed=2,
        underway=0,
        last=failed,
        recent=[*summary(ROBOT).recent, failed],
        events=[BrainEvent(at=AT + 30, severity=Severity.ERROR, message=HOSTILE)],
    )
    publish_summary(url, ROBOT, done)
    newest = page.locator("table[data-outcomes] tr[data-outcome]").first
    expect(newest).to_have_attribute("data-outcome", "failed", **expect_ms())
    expect(newest).to_contain_text("E_BLOCKED")
    expect(newest).to_contain_text(HOSTILE)  # the robot's markup is text
    expect(page.locator('[data-current-goal="none"]')).to_be_visible()
    expect(page.locator("[data-goal-counts]")).to_have_attribute("data-goal-counts", "3/2")
    expect(page.locator('[data-brain-events] li[data-severity="error"]')).to_contain_text(HOSTILE)
    expect(page.locator('[data-vital="battery"]')).to_have_text("0.82")
    assert page.locator("main img").count() == 0
    assert page.evaluate("window.pwned") is None
    assert page.evaluate("window.notReloaded") is True


def test_the_fleet_page_shows_goals_and_success_rates(
    ui: tuple[UiProc, str], browser: Browser, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    proc, url = ui
    publish_summary(url, "tb3-01", summary("tb3-01", completed=9, failed=1))
    publish_summary(url, "tb3-03", summary("tb3-03", completed=3, failed=3, stale=1))
    page = open_page(browser)
    page.goto(f"http://127.0.0.1:{proc.port}/")
    cell = page.locator('tr[data-robot="tb3-01"] td[data-goals]')
    expect(cell).to_have_text("9/1", **expect_ms())
    expect(page.locator('tr[data-robot="tb3-03"] td[data-goals]')).to_have_text("3/3 1 stale")
    expect(page.locator('tr[data-robot="tb3-02"] td[data-goals]')).to_have_text("unknown")
    rate = page.locator(f'table[data-rates] tr[data-revision="{REV1}"]')
    expect(rate).to_have_attribute("data-rate", "75%", **expect_ms())

    # A robot's goals fail: its cell and the rate follow on the open page.
    publish_summary(url, "tb3-01", summary("tb3-01", completed=9, failed=11))
    expect(cell).to_have_text("9/11", **expect_ms())
    expect(rate).to_have_attribute("data-rate", "46%", **expect_ms())
    rate.locator("a").click()  # the revision's page: what the ledger kept, and its robots now
    expect(page).to_have_url(f"http://127.0.0.1:{proc.port}/revisions/{REV1}", **expect_ms())
    kept = page.locator('[data-ledger="kept"] [data-total-rate]')
    expect(kept).to_have_attribute("data-total-rate", "70%", **expect_ms())
    expect(page.locator("[data-failure-codes]")).to_contain_text("NAV2_TIMEOUT ×3")
    live = page.locator(f'[data-live-goals] tr[data-revision="{REV1}"]')
    expect(live).to_have_attribute("data-rate", "46%", **expect_ms())
