"""The agent's unit tests fail on any phase change the supervisor refused: every path they drive
must stay inside agent/supervisor.py's TRANSITIONS."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def no_illegal_phase_change(caplog: pytest.LogCaptureFixture) -> Iterator[None]:
    yield
    refused = [
        r.getMessage()
        for r in caplog.get_records("call")
        if r.name == "robotconf.agent.supervisor" and "illegal phase change" in r.getMessage()
    ]
    assert refused == [], refused
