"""Fixtures of the browser tests: one headless Chromium per module, a page in a browser context
of its own (its own cookies) per test, and a real fleet with `robotconf ui` beside it."""

from __future__ import annotations

import contextlib
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.wire import AgentStatus
from tests.support import browser as support
from tests.support.fleet import GitLab, Proc, start_agent, start_reconciler
from tests.support.mosquitto import Mosquitto, find_mosquitto
from tests.support.ui import UiProc
from tests.support.watch import FleetWatch

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page


_OUTCOME = pytest.StashKey[bool]()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item,
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """Keeps whether a test's own body passed, for fixtures that check more at teardown."""
    report = yield
    if getattr(report, "when", None) == "call":
        item.stash[_OUTCOME] = bool(report.passed)
    return report


def passed(item: pytest.Item) -> bool:
    return item.stash.get(_OUTCOME, False)


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """Per module: no browser runs beside the rest of the suite (two cores, shared)."""
    why = support.missing()
    if why is not None:
        if support.required():
            pytest.fail(f"{why}: ./dev test installs it (the browser tests never run without)")
        pytest.skip(f"{why}; `./dev test` installs it")
    with support.chromium() as started:
        yield started


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    try:
        yield context.new_page()
    finally:
        context.close()


HELD = "tb3-01"  # its brain holds its agent off while the marker exists: Progressing on demand
TOKEN = "browser-test-operator-token-0123456789"


@dataclass
class UiFleet:
    """The example lab's robots with real agents, a reconciler and `robotconf ui` (with an
    operator token file) on one Mosquitto; `marker` is the file that keeps HELD's brain busy."""

    lab: GitLab
    broker: Mosquitto
    watch: FleetWatch
    folder: Path
    marker: Path
    agents: dict[str, Proc] = field(default_factory=dict)
    reconcilers: list[Proc] = field(default_factory=list)  # every one started, the last runs
    ui: UiProc | None = None
    converged: dict[str, AgentStatus] = field(default_factory=dict)

    @property
    def url(self) -> str:
        assert self.ui is not None
        return f"http://127.0.0.1:{self.ui.port}"

    @property
    def reconciler(self) -> Proc:
        return self.reconcilers[-1]

    def requests(self, revision: str | None = None) -> dict[str, RenderedRequest]:
        return self.lab.requests(revision)

    def start_reconciler(self) -> Proc:
        log = self.folder / f"reconciler-{len(self.reconcilers)}.log"
        self.reconcilers.append(start_reconciler(self.lab, self.broker.url, log))
        return self.reconciler

    def start_ui(self) -> UiProc:
        """As the docs start it: with the prefix and an operator token file."""
        token_file = self.folder / "operator-token"
        token_file.write_text(TOKEN + "\n", encoding="utf-8")
        token_file.chmod(0o600)
        options = ["--prefix", "robotconf", "--operator-token-file", str(token_file)]
        self.ui = UiProc(self.lab.root, self.broker.url, self.folder / "ui.log", *options)
        return self.ui


@contextlib.contextmanager
def ui_fleet_on(folder: Path, broker: Mosquitto) -> Iterator[UiFleet]:
    lab = GitLab(folder / "lab")
    marker = folder / "busy"
    marker.touch()
    state = UiFleet(lab, broker, FleetWatch(broker.url), folder, marker)
    try:
        for robot_id in lab.robots():
            hold = ["--hold-while", str(marker)] if robot_id == HELD else []
            state.agents[robot_id] = start_agent(lab, robot_id, broker.url, folder, hold)
        state.start_reconciler()
        state.converged = state.watch.wait_running(state.requests())
        state.start_ui()
        yield state
    finally:
        state.watch.close()
        for proc in [*state.reconcilers, *state.agents.values()]:
            proc.stop()
        if state.ui is not None:
            state.ui.stop()  # and no traceback in its log, whatever the browser did


@pytest.fixture(scope="module")
def ui_fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[UiFleet]:
    """One fleet for the module's tests, which leave it converged as they found it."""
    if find_mosquitto() is None:
        pytest.fail("mosquitto is not installed: run ./dev setup (tests never mock the broker)")
    broker = Mosquitto(tmp_path_factory.mktemp("ui-mosquitto"))
    broker.start()
    try:
        with ui_fleet_on(tmp_path_factory.mktemp("ui-fleet"), broker) as state:
            yield state
    finally:
        broker.kill()
