"""Fixtures shared by every test suite: a copy of the example lab, a real Mosquitto per test."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.lab import Lab
from tests.support.mosquitto import Mosquitto, find_mosquitto
from tests.support.watch import FleetWatch


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
