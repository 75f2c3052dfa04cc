"""Fixtures of the browser tests: one headless Chromium per module, a page in a browser context
of its own (its own cookies) per test, and a real fleet with `robotconf ui` beside it."""

from __future__ import annotations

import contextlib
import urllib.request
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from configurator.rendered import RenderedRequest
from contract.wire import AgentStatus
from tests.support import browser as support
from tests.support.fleet import GitLab, Proc, robotconf_argv, start_agent, start_reconciler
from tests.support.mosquitto import Mosquitto, find_mosquitto, free_port
from tests.support.watch import FleetWatch, wait_for

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
    """The example lab's robots with real agents, a reconciler and `robotconf ui` on one
    Mosquitto; `url` is the UI's address, `marker` the file that keeps HELD's brain busy."""

    lab: GitLab
    broker: Mosquitto
    watch: FleetWatch
    url: str
    marker: Path
    agents: dict[str, Proc] = field(default_factory=dict)
    procs: list[Proc] = field(default_factory=list)  # every reconciler and UI started
    reconciler: Proc | None = None
    converged: dict[str, AgentStatus] = field(default_factory=dict)
    folder: Path = Path()

    def requests(self, revision: str | None = None) -> dict[str, RenderedRequest]:
        return self.lab.requests(revision)

    def start_reconciler(self) -> Proc:
        log = self.folder / f"reconciler-{len(self.procs)}.log"
        self.reconciler = start_reconciler(self.lab, self.broker.url, log)
        self.procs.append(self.reconciler)
        return self.reconciler


def _healthy(url: str) -> bool:
    try:
        with urllib.request.urlopen(url + "/healthz", timeout=5) as answer:
            return bool(answer.status == 200)
    except OSError:
        return False


def start_ui(lab: GitLab, broker: Mosquitto, folder: Path, port: int) -> Proc:
    """`robotconf ui` with an operator token file, as the docs show it, on a free port."""
    token_file = folder / "operator-token"
    token_file.write_text(TOKEN + "\n", encoding="utf-8")
    token_file.chmod(0o600)
    argv = robotconf_argv(
        "ui", "--broker", broker.url, "--prefix", "robotconf", "--repo", str(lab.root),
        "--listen", f"127.0.0.1:{port}", "--operator-token-file", str(token_file),
    )  # fmt: skip
    return Proc(argv, folder / "ui.log")


@contextlib.contextmanager
def ui_fleet_on(folder: Path, broker: Mosquitto) -> Iterator[UiFleet]:
    lab = GitLab(folder / "lab")
    marker = folder / "busy"
    marker.touch()
    port = free_port()
    state = UiFleet(lab, broker, FleetWatch(broker.url), f"http://127.0.0.1:{port}", marker)
    state.folder = folder
    try:
        for robot_id in lab.robots():
            hold = ["--hold-while", str(marker)] if robot_id == HELD else []
            state.agents[robot_id] = start_agent(lab, robot_id, broker.url, folder, hold)
        state.start_reconciler()
        state.converged = state.watch.wait_running(state.requests())
        ui = start_ui(lab, broker, folder, port)
        state.procs.append(ui)
        wait_for(lambda: _healthy(state.url) or not ui.alive(), "the UI to answer /healthz")
        assert ui.alive(), ui.output()
        yield state
    finally:
        state.watch.close()
        for proc in [*state.procs, *state.agents.values()]:
            proc.stop()


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
