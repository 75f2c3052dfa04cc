"""Fixtures shared by every test suite: a copy of the example lab, a real Mosquitto per test."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.fleet import STARTED, kill_leftovers
from tests.support.lab import Lab
from tests.support.mosquitto import Mosquitto, find_mosquitto
from tests.support.schedule import longest_first
from tests.support.watch import FleetWatch

_SESSION_TMP_PREFIX = "robotconf-tests-"
_session_tmp = pytest.StashKey[Path]()


def pytest_configure(config: pytest.Config) -> None:
    """Every temporary file of the run, this process's and its children's (agents, brains,
    reconcilers), goes to one folder of the run, checked empty at the end: a test that leaves
    something in the system's temporary folder fails (`temporary_files_checked`).
    Other processes on the machine (another run, another helper) write there too, so comparing
    the system folder before and after could not tell whose entry is whose. pytest's own
    tmp_path folders stay where they were (the last three runs, kept for debugging)."""
    system = tempfile.gettempdir()
    os.environ.setdefault("PYTEST_DEBUG_TEMPROOT", system)
    folder = tempfile.mkdtemp(prefix=_SESSION_TMP_PREFIX, dir=system)
    config.stash[_session_tmp] = Path(folder)
    # Reconcilers keep their outcome ledger under $XDG_STATE_HOME unless given --state-dir:
    # the run's own, not the user's (~/.local/state), removed with the run's folder.
    os.environ["XDG_STATE_HOME"] = os.path.join(folder, ".state")
    os.environ["TMPDIR"] = folder
    tempfile.tempdir = folder
    config.addinivalue_line(
        "markers",
        "agents_apart: the fleet fixture runs an agent process per robot (fleet.agents), for "
        "tests that kill or start one robot; otherwise they share one process",
    )
    config.addinivalue_line(
        "markers",
        "robots(ID, ...): the reconciler tests' lab keeps only these robots of the example's "
        "fleet (a test of up's processes needs two, not six of them starting)",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under pytest-xdist, every worker's share of the run starts with some of the longest
    tests (tests/support/schedule.py). Every worker collects, in the same order."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if workers > 1:
        items[:] = longest_first([item.nodeid for item in items], items, workers)


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = config.stash.get(_session_tmp, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def temporary_files_checked(pytestconfig: pytest.Config) -> Iterator[None]:
    """Fails the run (an error at the last teardown) naming what tests left in the run's
    temporary folder; pytest_unconfigure then removes it, so /tmp stays clean either way."""
    yield
    folder = pytestconfig.stash[_session_tmp]
    left = sorted(entry.name for entry in folder.iterdir() if entry.name != ".state")
    assert not left, f"tests left these in the temporary folder (use tmp_path): {left}"


@pytest.fixture(autouse=True)
def processes_ended() -> Iterator[None]:
    """A test that fails half-way leaves no process of it running (a `status --watch`, an
    agent): they would outlive the run and load the machine. Fixtures of a wider scope are
    set up before this one: what they start is theirs to end."""
    since = len(STARTED)
    yield
    kill_leftovers(since)


@pytest.fixture
def mosquitto(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Mosquitto]:
    """A running broker on a free port (`.url`), killed at teardown; `stop()`/`start()` keep
    the port so that tests can take the broker away and bring it back."""
    if find_mosquitto() is None:
        pytest.fail("mosquitto is not installed: run ./dev setup (tests never mock the broker)")
    broker = Mosquitto(Path(tmp_path_factory.mktemp("mosquitto")))
    broker.start()
    try:
        yield broker
    finally:
        broker.kill()


@pytest.fixture
def lab(tmp_path: Path) -> Lab:
    """The example lab copied into a temporary folder (no git repository until committed)."""
    return Lab(tmp_path / "lab")


@pytest.fixture
def watch(mosquitto: Mosquitto) -> Iterator[FleetWatch]:
    """The test broker's fleet topics, watched (tests/support/watch.py)."""
    watcher = FleetWatch(mosquitto.url)
    try:
        yield watcher
    finally:
        watcher.close()
