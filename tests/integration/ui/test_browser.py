"""The fleet in a real browser: headless Chromium on `robotconf ui` of a real fleet (Mosquitto,
reconciler, agents with stand-in brains). A commit turns a row from Progressing to InSync
without a reload, a refused commit's diagnostic shows, the label filter narrows the rows, an
operator restarts a robot and a viewer cannot; keyboard, phone width, verdicts as text; a
robot's markup is text; a reconciler and a broker restart are shown, then recovered from, on
the same open page. The docs' screenshots come from here (ROBOTCONF_SCREENSHOTS=docs/images).

Relies on the DOM contract of issue 24 (`tr[data-robot][data-verdict]`,
`[data-reconciler-state]`, `[data-diagnostics] li`, `form[data-filter]`, `[data-robot-page]`,
`a[data-action="restart"]`, `form[data-confirm-restart]`, `[data-restart-outcome]`,
`form[data-login]`) and on two attributes of the UI's own: `[data-banner="broker"]`,
`[data-banner="reconciler"]`, and the restart outcome's state as `data-restart-outcome`'s value.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from robotconf.contract.wire import AgentState, AgentStatus, RobotDescription, Topics
from tests.integration.ui.conftest import HELD, TOKEN, UiFleet, passed
from tests.support.agents import publish
from tests.support.browser import screenshot_folders
from tests.support.fleet import pid_alive

if TYPE_CHECKING:
    from playwright.sync_api import Browser, ConsoleMessage, Page, Response

WAIT_MS = 60_000  # generous: CI machines are slow and shared; nothing asserts timing
ROW = "tr[data-robot]"
# In fleet.yaml, with no agent: the test plays its robot (tests/integration/reconciler/conftest.py
# runs the same line with an agent).
EXTRA = "  tb3-08: {scenario: delivery-gazebo, name: Second delivery bot}\n"


def expect_ms() -> dict[str, float]:
    return {"timeout": WAIT_MS}


# Every page a test opened, with what its console said in red: a script error or something
# the CSP refused (an inline script or style) fails the test.
OPENED: list[tuple[Page, list[str]]] = []


@pytest.fixture(autouse=True)
def pages_without_errors(request: pytest.FixtureRequest) -> Iterator[None]:
    OPENED.clear()
    yield
    try:
        if passed(request.node):  # a failed test has said what went wrong already
            said = {page.url: errors for page, errors in OPENED if errors}
            assert not said, f"the browser reported errors: {said}"
    finally:
        for page, _ in OPENED:
            page.context.close()
        OPENED.clear()


def open_page(browser: Browser, width: int = 1280, height: int = 900) -> Page:
    """A page in a new browser context: no cookie of another test's login."""
    page = browser.new_context(viewport={"width": width, "height": height}).new_page()
    errors: list[str] = []

    def said(message: ConsoleMessage) -> None:
        # A failed load is told with its address by the response below.
        if message.type == "error" and not message.text.startswith("Failed to load resource"):
            errors.append(message.text)

    def answered(response: Response) -> None:
        # Chromium asks for /favicon.ico by itself; the UI has none to give (no page names it).
        if response.status >= 400 and not response.url.endswith("/favicon.ico"):
            errors.append(f"{response.status} for {response.request.method} {response.url}")

    page.on("console", said)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("response", answered)
    OPENED.append((page, errors))
    return page


def rows(page: Page) -> dict[str, str]:
    """Robot id -> data-verdict of every row on the page."""
    found: dict[str, str] = page.eval_on_selector_all(
        ROW,
        "rows => Object.fromEntries(rows.map(r => [r.dataset.robot, r.dataset.verdict]))",
    )
    return found


def login(page: Page, url: str) -> None:
    """As an operator: the login form with the token of --operator-token-file."""
    from playwright.sync_api import expect

    page.goto(f"{url}/login")
    form = page.locator("form[data-login]")
    form.locator("input[name=token]").fill(TOKEN)
    with page.expect_response(lambda r: r.request.method == "POST", **expect_ms()) as sent:
        form.locator("input[name=token]").press("Enter")
    answer = sent.value
    assert answer.status == 303, f"the login answered {answer.status}: {page.inner_text('main')}"
    expect(page).not_to_have_url(re.compile(r"/login\b"), **expect_ms())


def test_a_commit_turns_a_row_from_progressing_to_in_sync_live(
    ui_fleet: UiFleet, browser: Browser
) -> None:
    from playwright.sync_api import expect

    page = open_page(browser)
    page.goto(ui_fleet.url + "/")
    row = page.locator(f'tr[data-robot="{HELD}"]')
    expect(row).to_have_attribute("data-verdict", "InSync", **expect_ms())
    page.evaluate("window.notReloaded = true")  # gone if the page were loaded again

    # HELD's brain holds its agent off: the new request waits (deferred), the row Progressing.
    lab = ui_fleet.lab
    lab.replace("configs/scenarios/delivery-gazebo.yaml", "move_speed: 0.1", "move_speed: 0.12")
    head = lab.commit("slower delivery")
    ui_fleet.watch.wait_state(HELD, AgentState.DEFERRED)
    expect(row).to_have_attribute("data-verdict", "Progressing", **expect_ms())
    expect(row).to_contain_text("Progressing")

    ui_fleet.marker.unlink()  # the brain's task is done: the agent starts the new request
    expect(row).to_have_attribute("data-verdict", "InSync", **expect_ms())
    expect(row).to_contain_text("InSync")
    assert page.evaluate("window.notReloaded") is True
    ui_fleet.converged = ui_fleet.watch.wait_running(ui_fleet.requests(head))


def test_a_refused_commit_shows_its_diagnostic_then_clears(
    ui_fleet: UiFleet, browser: Browser, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    page = open_page(browser)
    page.goto(ui_fleet.url + "/")
    box = page.locator("[data-reconciler-state]")
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())
    lab = ui_fleet.lab
    scenario = "configs/scenarios/delivery-gazebo.yaml"
    lab.replace(scenario, "capability: turtlebot3-camera", "capability: nope")
    lab.commit("typo")
    expect(box).to_have_attribute("data-reconciler-state", "Stalled", **expect_ms())
    diagnostic = page.locator("[data-diagnostics] li").filter(has_text="nope")
    expect(diagnostic).to_have_count(1, **expect_ms())
    # file:line:col CODE message, as `robotconf validate` points at it.
    expect(diagnostic).to_have_text(
        re.compile(rf"{re.escape(scenario)}:3:13\b.*\bRC206\b.*unknown capability .*'nope'")
    )
    for folder in screenshot_folders(tmp_path):  # the docs' fleet picture: a refused commit
        page.screenshot(path=str(folder / "ui-fleet.png"), full_page=True)

    lab.replace(scenario, "capability: nope", "capability: turtlebot3-camera")
    lab.commit("fix the typo")
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())
    expect(page.locator("[data-diagnostics] li")).to_have_count(0, **expect_ms())


def test_the_label_filter_narrows_the_rows(ui_fleet: UiFleet, browser: Browser) -> None:
    from playwright.sync_api import expect

    page = open_page(browser)
    page.goto(ui_fleet.url + "/")
    expect(page.locator(ROW)).to_have_count(len(ui_fleet.lab.robots()), **expect_ms())
    form = page.locator("form[data-filter]")
    form.locator("input[name=selector]").fill("site=robotics-lab")
    form.locator("input[name=selector]").press("Enter")
    expect(page).to_have_url(re.compile(r"[?&]selector=site%3Drobotics-lab\b"), **expect_ms())
    expect(page.locator(ROW)).to_have_count(2, **expect_ms())
    assert set(rows(page)) == {"tb3-04", "tb3-07"}

    page.goto(ui_fleet.url + "/?q=tb3-0&selector=ring%3Dcanary")  # the same query as a link
    expect(page.locator(ROW)).to_have_count(2, **expect_ms())
    assert set(rows(page)) == {"tb3-01", "tb3-03"}

    # The verdict and the id search from the form too: no robot is Degraded here.
    form = page.locator("form[data-filter]")
    form.locator("[name=verdict]").select_option("Degraded")
    form.locator("input[name=q]").fill("tb3-0")
    form.locator("input[name=q]").press("Enter")
    expect(page).to_have_url(re.compile(r"[?&]verdict=Degraded\b"), **expect_ms())
    expect(page.locator(ROW)).to_have_count(0, **expect_ms())


def tab_to(page: Page, selector: str, limit: int = 100) -> None:
    """Presses Tab until the focus is on an element matching `selector`."""
    for _ in range(limit):
        page.keyboard.press("Tab")
        if page.evaluate("s => !!document.activeElement?.matches(s)", selector):
            return
    raise AssertionError(f"Tab never reached {selector} in {limit} presses")


def test_an_operator_restarts_a_robot(ui_fleet: UiFleet, browser: Browser, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    robot = "tb3-04"
    before = ui_fleet.watch.status(robot)
    assert before is not None and before.state is AgentState.RUNNING and before.pid
    page = open_page(browser)
    login(page, ui_fleet.url)
    page.goto(f"{ui_fleet.url}/robots/{robot}")
    expect(page.locator(f'[data-robot-page="{robot}"]')).to_be_visible(**expect_ms())
    asked = time.time()
    # With the keyboard alone: Tab to the link, Enter; Tab to the confirmation's button, Enter.
    tab_to(page, 'a[data-action="restart"]')
    page.keyboard.press("Enter")
    confirm = page.locator("form[data-confirm-restart]")
    expect(confirm).to_be_visible(**expect_ms())
    expect(confirm.locator("input[name=csrf]")).to_have_count(1)
    tab_to(page, "form[data-confirm-restart] :is(button, input[type=submit])")
    page.keyboard.press("Enter")
    expect(page).to_have_url(re.compile(rf"/robots/{robot}$"), **expect_ms())
    outcome = page.locator("[data-restart-outcome]")
    expect(outcome).to_be_visible(**expect_ms())
    # Pending until the robot confirms; the page's script shows the confirmation by itself.
    expect(outcome).to_have_attribute("data-restart-outcome", "confirmed", **expect_ms())

    # The agent really started its brain again, recording the request from the desk.
    after = ui_fleet.watch.wait_for(
        robot,
        lambda s: (
            s.state is AgentState.RUNNING
            and s.pid != before.pid
            and s.restart_requested_at is not None
            and s.restart_requested_at >= asked - 1
        ),
        "a new brain for the UI's restart",
    )
    assert after.restart_requested_by and after.digest == before.digest
    assert not pid_alive(before.pid)
    ui_fleet.converged[robot] = after
    # The brain's log, followed live through the desk channel, says so too.
    tail = page.locator("pre[data-log-tail]")
    expect(tail).to_contain_text(
        f"restart requested by {after.restart_requested_by}", **expect_ms()
    )
    for folder in screenshot_folders(tmp_path):  # the docs' robot picture: an operator's
        page.screenshot(path=str(folder / "ui-robot.png"), full_page=True)

    # The same cookie without the form's CSRF token is refused.
    answer = page.request.post(f"{ui_fleet.url}/robots/{robot}/restart", form={"csrf": "x"})
    assert answer.status == 403


def test_a_viewer_sees_no_restart_and_cannot_post_one(ui_fleet: UiFleet, browser: Browser) -> None:
    from playwright.sync_api import expect

    robot = "tb3-04"
    before = ui_fleet.watch.status(robot)
    assert before is not None
    page = open_page(browser)
    page.goto(f"{ui_fleet.url}/robots/{robot}")
    expect(page.locator(f'[data-robot-page="{robot}"]')).to_be_visible(**expect_ms())
    expect(page.locator('a[data-action="restart"]')).to_have_count(0)
    assert page.request.get(f"{ui_fleet.url}/robots/{robot}/logs").status == 401
    answer = page.request.post(f"{ui_fleet.url}/robots/{robot}/restart", form={"csrf": "x"})
    assert answer.status == 401
    wrong = page.request.post(
        f"{ui_fleet.url}/robots/{robot}/restart",
        headers={"Authorization": "Bearer not-the-operator-token"},
    )
    assert wrong.status in (401, 403)
    now = ui_fleet.watch.status(robot)
    assert now is not None and now.restart_requested_at == before.restart_requested_at


def test_keyboard_reaches_the_filter_and_every_row_link(
    ui_fleet: UiFleet, browser: Browser
) -> None:
    from playwright.sync_api import expect

    page = open_page(browser)
    page.goto(ui_fleet.url + "/")
    expect(page.locator(ROW)).to_have_count(len(ui_fleet.lab.robots()), **expect_ms())
    focusable = page.locator("a[href], button, input, select, textarea, [tabindex]").count()
    reached: set[str] = set()
    for _ in range(focusable + 2):
        page.keyboard.press("Tab")
        reached.add(
            page.evaluate(
                """() => {
                    const el = document.activeElement;
                    if (!el) return "";
                    if (el.closest("form[data-filter]") && el.name) return "filter:" + el.name;
                    const row = el.closest("tr[data-robot]");
                    if (row && el.tagName === "A") return "row:" + row.dataset.robot;
                    return "";
                }"""
            )
        )
    wanted = {"filter:selector"} | {f"row:{r}" for r in ui_fleet.lab.robots()}
    assert wanted <= reached, f"Tab never reached {sorted(wanted - reached)}"


def page_width(page: Page) -> tuple[int, int]:
    """How wide the page is, and how wide its window: more is a horizontal scroll."""
    found: tuple[int, int] = page.evaluate(
        "[document.documentElement.scrollWidth, document.documentElement.clientWidth]"
    )
    return found


@pytest.mark.parametrize("width", [390])
def test_a_phone_width_needs_no_horizontal_scroll(
    ui_fleet: UiFleet, browser: Browser, width: int
) -> None:
    from playwright.sync_api import expect

    page = open_page(browser, width=width, height=844)
    page.goto(ui_fleet.url + "/")
    expect(page.locator(ROW)).to_have_count(len(ui_fleet.lab.robots()), **expect_ms())
    scroll, inner = page_width(page)
    assert scroll <= inner, f"the fleet page is {scroll} px wide in a {inner} px window"
    for robot, verdict in rows(page).items():  # not by colour alone: the verdict is text
        text = page.locator(f'tr[data-robot="{robot}"]').inner_text()
        assert verdict in text, (robot, verdict, text)
    # The table may scroll in its own box, but each robot's id and verdict are in sight.
    hidden = page.eval_on_selector_all(
        ROW,
        """rows => rows.filter(row => {
            const verdict = [...row.querySelectorAll("*")].find(
                e => e.children.length === 0 && e.textContent.trim() === row.dataset.verdict);
            const link = row.querySelector("a");
            return ![verdict, link].every(
                e => e && e.getBoundingClientRect().right <= window.innerWidth);
        }).map(row => row.dataset.robot)""",
    )
    assert hidden == [], f"id or verdict out of sight at {width} px: {hidden}"

    page.goto(ui_fleet.url + "/robots/tb3-04")
    expect(page.locator('[data-robot-page="tb3-04"]')).to_be_visible(**expect_ms())
    scroll, inner = page_width(page)
    assert scroll <= inner, f"a robot's page is {scroll} px wide in a {inner} px window"


HOSTILE = '<img src=x onerror="document.title=1"></td></tr><tr data-robot="evil"><td>'


def test_a_robots_hostile_text_is_text_on_the_live_page(
    ui_fleet: UiFleet, browser: Browser
) -> None:
    """A robot in fleet.yaml whose agent never came reports a status full of markup: its row
    (patched in live) and its page show it as text, and nothing else changes."""
    from playwright.sync_api import expect

    lab, topics, robot = ui_fleet.lab, Topics(), "tb3-08"
    lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml") + EXTRA)
    lab.commit("a robot whose agent is not there yet")
    page = open_page(browser)
    page.goto(ui_fleet.url + "/")
    row = page.locator(f'tr[data-robot="{robot}"]')
    expect(row).to_have_attribute("data-verdict", "Offline", **expect_ms())
    title = page.title()
    description = RobotDescription(id=robot, name="<script>document.title=2</script>")
    status = AgentStatus(robot_id=robot, state=AgentState.FAILED, message=HOSTILE)
    try:
        publish(
            ui_fleet.broker.url, topics.description(robot), description.model_dump_json().encode()
        )
        publish(ui_fleet.broker.url, topics.status(robot), status.model_dump_json().encode())
        expect(row).to_have_attribute("data-verdict", "Degraded", **expect_ms())
        expect(row).to_contain_text(HOSTILE)
        assert row.locator("img, script").count() == 0
        assert page.locator('tr[data-robot="evil"]').count() == 0
        assert page.title() == title
        # Nothing else changed: the other rows as they were.
        assert rows(page) == {**dict.fromkeys(lab.robots(), "InSync"), robot: "Degraded"}
        page.goto(f"{ui_fleet.url}/robots/{robot}")
        expect(page.locator(f'[data-robot-page="{robot}"]')).to_contain_text(HOSTILE)
        assert page.locator("main img, main script").count() == 0
    finally:
        lab.write("configs/fleet.yaml", lab.read("configs/fleet.yaml").replace(EXTRA, ""))
        lab.commit("not that robot after all")
        for topic in (topics.status(robot), topics.description(robot)):
            publish(ui_fleet.broker.url, topic, b"")
    page.goto(ui_fleet.url + "/")
    expect(page.locator(ROW)).to_have_count(len(lab.robots()), **expect_ms())


def test_the_page_shows_a_reconciler_and_a_broker_restart_then_recovers(
    ui_fleet: UiFleet, browser: Browser
) -> None:
    """Last in the module: it takes the fleet's reconciler and broker away and back."""
    from playwright.sync_api import expect

    page = open_page(browser)
    page.goto(ui_fleet.url + "/")
    box = page.locator("[data-reconciler-state]")
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())
    page.evaluate("window.notReloaded = true")
    reconciler_banner = page.locator('[data-banner="reconciler"]')
    broker_banner = page.locator('[data-banner="broker"]')
    expect(reconciler_banner).to_have_count(0)

    assert ui_fleet.reconciler.stop() == 0
    expect(reconciler_banner).to_be_visible(**expect_ms())
    ui_fleet.start_reconciler()
    expect(reconciler_banner).to_have_count(0, **expect_ms())
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())

    ui_fleet.broker.stop()
    expect(broker_banner).to_be_visible(**expect_ms())
    ui_fleet.broker.start()
    expect(broker_banner).to_have_count(0, **expect_ms())
    ui_fleet.watch.wait_running(ui_fleet.requests())
    for robot in ui_fleet.lab.robots():
        row = page.locator(f'tr[data-robot="{robot}"]')
        expect(row).to_have_attribute("data-verdict", "InSync", **expect_ms())
    expect(box).to_have_attribute("data-reconciler-state", "Ready", **expect_ms())
    assert page.evaluate("window.notReloaded") is True
