"""Property: whatever desks with fast clocks sent before, a restart from a correct clock is
carried out, and no restart carried out is carried out again, across agent restarts too."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from robotconf.agent.admission import (
    MAX_RESTARTS_AHEAD,
    RESTART_MAX_AGE,
    Reject,
    Restart,
    RestartMemory,
    interpret_restart,
)
from robotconf.agent.workdir import RestartLedger
from robotconf.contract.launch import RestartRequest

START = 1_800_000_000.0

# (seconds the robot's clock moves on, what arrives): a restart from a correct clock, one from
# a desk whose clock runs ahead by that much, a replay of the n-th restart carried out so
# far, or the agent restarting (its memory read back from its work directory).
events = st.lists(
    st.tuples(
        st.floats(0.001, 120.0),
        st.one_of(
            st.just(("correct", 0.0)),
            st.tuples(st.just("ahead"), st.floats(0.001, RESTART_MAX_AGE - 0.001)),
            st.tuples(st.just("replay"), st.floats(0, 1)),
            st.just(("agent restart", 0.0)),
        ),
    ),
    max_size=40,
)


@given(events)
def test_correct_clocks_are_never_locked_out_and_nothing_runs_twice(
    steps: list[tuple[float, tuple[str, float]]],
) -> None:
    folder = Path(tempfile.mkdtemp(prefix="robotconf-fuzz-restarts-"))
    try:
        ledger = RestartLedger(folder)
        now = START
        carried: list[bytes] = []  # the payloads carried out, in order
        ahead_sent = 0
        for moved, (what, value) in steps:
            now += moved
            if what == "agent restart":
                ledger = RestartLedger(folder)
                continue
            if what == "replay":
                if not carried:
                    continue
                payload = carried[int(value * (len(carried) - 1))]
            else:
                if what == "ahead":
                    if ahead_sent >= MAX_RESTARTS_AHEAD:
                        continue  # beyond, refused on purpose (a unit test says so)
                    ahead_sent += 1
                issued = round(now + value, 6)
                payload = RestartRequest(
                    robot_id="tb3-01",
                    requested_by="fastdesk" if what == "ahead" else "ops",
                    issued_at=issued,
                ).payload()
            memory = RestartMemory.of(ledger.watermark, ledger.ahead)
            outcome = interpret_restart(payload, "tb3-01", None, memory, now)
            if what == "replay":
                assert isinstance(outcome, Reject), outcome
                continue
            # From a correct clock, or ahead (within the bound): carried out, whatever came before.
            assert isinstance(outcome, Restart), outcome
            done = memory.carried_out(outcome, now)
            assert done.watermark is not None and done.watermark <= now
            ledger.record(done.watermark, done.ahead_entries())
            carried.append(payload)
    finally:
        shutil.rmtree(folder)
