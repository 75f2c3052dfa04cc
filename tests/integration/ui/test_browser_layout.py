"""Trouble first, at a laptop's width (issue 32, item 1), in a real browser: headless Chromium at
1280x800 and 390x844 on `robotconf ui` of a real Mosquitto.

On the example lab's fleet (real reconciler and agents) a robot whose brain failed, with a long
why: on the fleet page and on its page, nothing that says what is wrong (robot, verdict, why) is
cut off or out of the window; its row is the first, in the first screen without scrolling; the
reconciler's box (Ready, nothing to say) and the success rates are one line each, the
reconciler's opens by itself on a refused commit and folds again when it is fixed, and a box the
reader opened stays open across live updates. Digests and revisions look different.

On a generated 10,000-robot fleet (bench/generate.py; the robots' statuses and the reconciler's,
rollout included, published as they would be, no reconciler running) one robot failed: its row
is first and in sight, the worst 500 shown and the rest counted; a Complete rollout is one line
and a Paused one opens.

DOM contract (docs/architecture.md): `td.why` in each row (third, after the verdict), the robot
page's `p.why` and history `td.why`; `details[data-fold="open|closed"]` in the `reconciler`,
`rollout` and `rates` boxes (open when something is wrong); `a.rev[title]` for a revision,
`code.digest[title]` for a digest.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from robotconf.configurator.brokerconf import queue_lines
from robotconf.contract.wire import (
    AgentState,
    AgentStatus,
    ReconcilerStatus,
    RolloutStatus,
    Topics,
)
from tests.integration.ui.conftest import UiFleet
from tests.integration.ui.test_browser import (  # noqa: F401 (pages_without_errors: autouse)
    ROW,
    expect_ms,
    open_page,
    pages_without_errors,
    rows,
)
from tests.support.agents import publish, publish_many
from tests.support.browser import screenshot_folders
from tests.support.mosquitto import Mosquitto, find_mosquitto
from tests.support.ui import UiProc

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

LAPTOP = (1280, 800)
PHONE = (390, 844)
TROUBLED = "tb3-08"
EXTRA = "  tb3-08: {scenario: delivery-gazebo, name: Second delivery bot}\n"
WHY = (
    "brain exited with 1: navigation2 lifecycle manager could not activate bt_navigator "
    "(timeout waiting for /tb3_08/amcl_pose after 30 s; map server not reachable on the "
    "robot's domain)"
)
ROOT = Path(__file__).resolve().parents[3]

# Elements of `selector` that are cut: beyond the window's right or left edge, beyond their
# scrolling box's visible part, or their own text clipped (wider than the element shows).
CUT = """selector => [...document.querySelectorAll(selector)].filter(el => {
    const box = el.getBoundingClientRect();
    const scroller = el.closest(".scroll");
    const frame = scroller ? scroller.getBoundingClientRect() : {left: 0, right: innerWidth};
    const right = Math.min(innerWidth, frame.right), left = Math.max(0, frame.left);
    return box.right > right + 0.5 || box.left < left - 0.5 || el.scrollWidth > el.clientWidth + 1;
}).map(el => (el.closest("tr") && el.closest("tr").dataset.robot) || el.textContent)"""

# A folded box: [its summary's height in lines of its heading, open].
FOLD = """box => {
    const details = box.querySelector(":scope > details[data-fold]");
    const summary = details.querySelector(":scope > summary");
    const line = parseFloat(getComputedStyle(summary.querySelector("h2")).lineHeight);
    return [summary.getBoundingClientRect().height / line, details.open];
}"""


def cut(page: Page, selector: str) -> list[str]:
    found: list[str] = page.evaluate(CUT, selector)
    return found


def folded(page: Page, box: str) -> tuple[float, bool]:
    """(lines of its summary, whether it is open) of `[data-box=box]`."""
    lines, opened = page.locator(f'[data-box="{box}"]').evaluate(FOLD)
    return float(lines), bool(opened)


def assert_one_line(page: Page, box: str) -> None:
    lines, opened = folded(page, box)
    assert not opened and lines < 1.5, f"the {box} box is {lines:.1f} lines, open: {opened}"


def assert_first_row_in_sight(page: Page, robot: str, height: int) -> None:
    """The worst row is `robot`'s, and its id and verdict are in the first screen, not
    scrolled to."""
    first = page.locator(ROW).first
    assert first.get_attribute("data-robot") == robot
    assert page.evaluate("scrollY") == 0
    for part in ("th", "td.verdict .badge"):
        box = first.locator(part).bounding_box()
        assert box is not None, part
        assert box["y"] >= 0 and box["y"] + box["height"] <= height, (part, box)


def assert_nothing_wrong_is_cut(page: Page, width: int) -> None:
    """The whole page fits the window's width; robot, verdict and why are never cut."""
    scroll, inner = page.evaluate(
        "[document.documentElement.scrollWidth, document.documentElement.clientWidth]"
    )
    assert scroll <= inner, f"the page is {scroll} px wide in a {inner} px window"
    for what in ("tr[data-robot] > th", "tr[data-robot] td.verdict", "tr[data-robot] td.why"):
        assert cut(page, what) == [], f"{what} cut at {width} px"


@pytest.fixture
def troubled(ui_fleet: UiFleet) -> Iterator[str]:
    """TROUBLED in fleet.yaml without an agent, its status a failed brain with a long why."""
    lab, topics, broker = ui_fleet.lab, Topics(), ui_fleet.broker.url
    lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml") + EXTRA)
    lab.commit("a robot whose brain fails")
    status = AgentStatus(robot_id=TROUBLED, state=AgentState.FAILED, message=WHY)
    publish(broker, topics.status(TROUBLED), status.model_dump_json().encode())
    try:
        yield TROUBLED
    finally:
        lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml").replace(EXTRA, ""))
        lab.commit("not that robot after all")
        publish(broker, topics.status(TROUBLED), b"")


def test_trouble_is_in_sight_and_whole_at_a_laptops_and_a_phones_width(
    ui_fleet: UiFleet, troubled: str, browser: Browser, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    for width, height in (LAPTOP, PHONE):
        page = open_page(browser, width, height)
        page.goto(ui_fleet.url + "/")
        row = page.locator(f'tr[data-robot="{troubled}"]')
        expect(row).to_have_attribute("data-verdict", "Degraded", **expect_ms())
        expect(page.locator(ROW)).to_have_count(len(ui_fleet.lab.robots()), **expect_ms())
        expect(page.locator('[data-box="reconciler"]')).to_have_attribute(
            "data-reconciler-state", "Ready", **expect_ms()
        )
        expect(row.locator("td.why")).to_have_text(WHY)
        assert rows(page)[troubled] == "Degraded"
        assert_nothing_wrong_is_cut(page, width)
        if (width, height) == LAPTOP:
            assert_first_row_in_sight(page, troubled, height)
            assert_one_line(page, "reconciler")
            assert_one_line(page, "rates")  # the example lab's 5 scenarios: folded
            for folder in screenshot_folders(tmp_path):  # the docs' picture: trouble first
                page.screenshot(path=str(folder / "ui-trouble-first.png"))

        page.goto(f"{ui_fleet.url}/robots/{troubled}")
        box = page.locator('[data-box="robot"]')
        expect(box).to_have_attribute("data-verdict", "Degraded", **expect_ms())
        expect(box.locator("p.why")).to_have_text(WHY)
        expect(box.locator("table[data-history] td.why").first).to_have_text(WHY)
        scroll, inner = page.evaluate(
            "[document.documentElement.scrollWidth, document.documentElement.clientWidth]"
        )
        assert scroll <= inner, f"a robot's page is {scroll} px wide in {inner} px"
        for what in ('[data-box="robot"] .badge', "p.why", "table[data-history] td.why"):
            assert cut(page, what) == [], f"{what} cut at {width} px"
        assert box.bounding_box() is not None


def test_digests_and_revisions_look_different(ui_fleet: UiFleet, browser: Browser) -> None:
    from playwright.sync_api import expect

    robot = "tb3-04"
    page = open_page(browser, *LAPTOP)
    page.goto(f"{ui_fleet.url}/robots/{robot}")
    launch = page.locator("[data-launch]")
    revision = launch.locator("a.rev")
    expect(revision).to_have_count(1, **expect_ms())
    digest = launch.locator("code.digest")
    applied = ui_fleet.watch.launch(robot)
    assert applied is not None
    full_digest, full_revision = applied["digest"], applied["revision"]
    # A revision: 12 hex digits, a link to its commit's page, the whole commit in its title.
    expect(revision).to_have_text(full_revision[:12])
    expect(revision).to_have_attribute("title", f"commit {full_revision}")
    expect(revision).to_have_attribute("href", f"/revisions/{full_revision}")
    # A digest: labelled sha256:, 8 hex digits, not a link, the whole digest in its title.
    expect(digest).to_have_text("sha256:" + full_digest.removeprefix("sha256:")[:8])
    expect(digest).to_have_attribute("title", full_digest)
    assert digest.evaluate("e => e.closest('a')") is None
    looks = """e => { const s = getComputedStyle(e);
        return [s.color, s.backgroundColor, s.borderStyle, s.fontSize]; }"""
    assert digest.evaluate(looks) != revision.locator("code").evaluate(looks)
    # The fleet's rows say digests the same way.
    page.goto(ui_fleet.url + "/")
    cells = page.locator(f'tr[data-robot="{robot}"] code.digest')
    expect(cells).to_have_count(2, **expect_ms())
    expect(cells.first).to_have_attribute("title", full_digest)


def test_the_reconciler_box_opens_on_trouble_and_keeps_a_readers_choice(
    ui_fleet: UiFleet, browser: Browser
) -> None:
    from playwright.sync_api import expect

    page = open_page(browser, *LAPTOP)
    page.goto(ui_fleet.url + "/")
    box = page.locator('[data-box="reconciler"]')
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())
    assert_one_line(page, "reconciler")
    lab = ui_fleet.lab

    # The reader opens it: a new commit applied (the box sent again, still Ready) keeps it open.
    box.locator("summary").click()
    assert folded(page, "reconciler")[1]
    applied = box.locator('details[data-fold="closed"] a.rev').first
    guide = "configs/scenarios/guide-gazebo.yaml"  # not HELD's: its agent follows at once
    lab.replace(guide, "max_linear_speed: 0.18", "max_linear_speed: 0.17")
    head = lab.commit("a little slower")
    expect(applied).to_have_attribute("title", f"commit {head}", **expect_ms())
    assert folded(page, "reconciler")[1], "the box the reader opened folded on an update"

    # A refused commit: the page opens it (and would have had it been closed), diagnostics in sight.
    box.locator("summary").click()
    assert not folded(page, "reconciler")[1]
    scenario = "configs/scenarios/delivery-gazebo.yaml"
    lab.replace(scenario, "capability: turtlebot3-camera", "capability: nope")
    lab.commit("typo")
    expect(box).to_have_attribute("data-reconciler-state", "Stalled", **expect_ms())
    expect(box.locator('details[data-fold="open"]')).to_have_count(1, **expect_ms())
    expect(box.locator("[data-diagnostics] li").first).to_be_visible()
    assert folded(page, "reconciler")[1]

    # Fixed: one line again.
    lab.replace(scenario, "capability: nope", "capability: turtlebot3-camera")
    lab.replace(guide, "max_linear_speed: 0.17", "max_linear_speed: 0.18")
    fixed = lab.commit("fix the typo")
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())
    expect(box.locator('details[data-fold="closed"]')).to_have_count(1, **expect_ms())
    assert_one_line(page, "reconciler")
    ui_fleet.converged = ui_fleet.watch.wait_running(ui_fleet.requests(fixed))


# ------------------------------------------------------------------ a 10,000-robot fleet

ROBOTS = 10_000
WORST = "robot-00042"  # any of the generated fleet


def generate_lab(target: Path, robots: int) -> None:
    """bench/generate.py's lab of `robots` robots, committed (under a second for 10,000)."""
    spec = importlib.util.spec_from_file_location("bench_generate", ROOT / "bench" / "generate.py")
    assert spec is not None and spec.loader is not None
    generate: Any = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = generate  # its dataclasses look their module up
    spec.loader.exec_module(generate)
    generate.generate(target, generate.Sizes(robots=robots), use_git=True)


def reconciler_status(rollout: RolloutStatus) -> bytes:
    """A Ready reconciler's retained status, its heartbeat now (not stale for an hour)."""
    now = time.time()
    status = ReconcilerStatus(
        state="Ready", ready=True, reason="Applied", branch="main",
        last_applied_revision=rollout.revision, heartbeat=now, interval=3600.0,
        robots=ROBOTS, rollout=rollout,
    )  # fmt: skip
    return status.model_dump_json().encode()


def rollout_status(state: str, revision: str) -> RolloutStatus:
    return RolloutStatus.model_validate(
        {
            "revision": revision,
            "stable_revision": revision,
            "state": state,
            "wave": 2,
            "waves": 3,
            "wave_name": "all",
            "counts": {"healthy": ROBOTS - 1, "failed": 0, "pending": 1},
            "pending": [WORST],
            "message": "paused by fleet.yaml (rollout.paused: true)" if state == "Paused" else "",
        }
    )


@dataclass
class BigFleet:
    ui: UiProc
    broker: Mosquitto
    revision: str  # the generated lab's commit

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.ui.port}"


@pytest.fixture(scope="module")
def big_fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BigFleet]:
    """`robotconf ui` on the generated 10,000-robot lab: every robot's agent running (its
    request not published: Progressing), WORST's brain failed, a Ready reconciler with a
    Complete rollout; a broker whose queue is sized for the fleet (robotconf broker-config)."""
    if find_mosquitto() is None:
        pytest.fail("mosquitto is not installed: run ./dev setup (tests never mock the broker)")
    folder = tmp_path_factory.mktemp("big-fleet")
    generate_lab(folder / "lab", ROBOTS)
    (folder / "broker").mkdir()
    broker = Mosquitto(folder / "broker", extra_config=queue_lines(ROBOTS))
    broker.start()
    topics = Topics()
    statuses = {
        topics.status(robot): AgentStatus(
            robot_id=robot,
            state=AgentState.FAILED if robot == WORST else AgentState.RUNNING,
            digest="sha256:" + "0" * 64,
            message=WHY if robot == WORST else "",
        )
        .model_dump_json()
        .encode()
        for robot in (f"robot-{n:05d}" for n in range(ROBOTS))
    }
    revision = head_revision(folder / "lab")
    statuses[topics.reconciler_status] = reconciler_status(rollout_status("Complete", revision))
    ui = None
    try:
        publish_many(broker.url, statuses)
        ui = UiProc(folder / "lab", broker.url, folder / "ui.log", "--prefix", "robotconf")
        yield BigFleet(ui, broker, revision)
    finally:
        if ui is not None:
            ui.stop()
        broker.kill()


def head_revision(repo: Path) -> str:
    done = subprocess.run(
        ["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
    )
    return done.stdout.strip()


def test_a_robot_in_trouble_is_in_sight_on_a_ten_thousand_robot_fleet(
    big_fleet: BigFleet, browser: Browser
) -> None:
    from playwright.sync_api import expect

    ui, broker, url = big_fleet.ui, big_fleet.broker, big_fleet.url
    body = ui.wait_page("/", lambda b: f"{ROBOTS} robots in the fleet" in b, "the whole fleet")
    assert f'data-robot="{WORST}" data-verdict="Degraded"' in body
    width, height = LAPTOP
    page = open_page(browser, width, height)
    page.goto(url + "/")
    expect(page.locator(f'tr[data-robot="{WORST}"]')).to_have_attribute(
        "data-verdict", "Degraded", **expect_ms()
    )
    expect(page.locator(ROW)).to_have_count(500)  # the worst 500, the others counted
    expect(page.locator("[data-more]")).to_contain_text(f"worst 500 of {ROBOTS}")
    assert_first_row_in_sight(page, WORST, height)
    assert_nothing_wrong_is_cut(page, width)
    assert_one_line(page, "reconciler")
    assert_one_line(page, "rollout")
    expect(page.locator('[data-box="rollout"]')).to_have_attribute("data-rollout-state", "Complete")

    # The rollout pauses: its box opens by itself, live; the failed robot stays in sight.
    paused = reconciler_status(rollout_status("Paused", big_fleet.revision))
    publish(broker.url, Topics().reconciler_status, paused)
    box = page.locator('[data-box="rollout"]')
    expect(box).to_have_attribute("data-rollout-state", "Paused", **expect_ms())
    expect(box.locator('details[data-fold="open"]')).to_have_count(1)
    assert folded(page, "rollout")[1]
    expect(box.locator('[data-group="pending"]')).to_contain_text(WORST)
    assert_first_row_in_sight(page, WORST, height)
