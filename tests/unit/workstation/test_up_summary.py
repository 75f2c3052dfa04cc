"""`robotconf up`'s line output: robots per verdict, and the rollout while one is under way."""

from __future__ import annotations

from robotconf.contract.wire import ReconcilerStatus, RolloutStatus
from robotconf.readmodel.verdicts import FleetStatus
from robotconf.workstation.up import summary


def fleet_with(rollout: RolloutStatus | None) -> FleetStatus:
    status = ReconcilerStatus(state="Progressing", ready=False, rollout=rollout)
    return FleetStatus([], status, "test")


def test_a_rollout_under_way_is_in_the_line() -> None:
    rollout = RolloutStatus(
        revision="a" * 40, state="Progressing", wave=0, waves=3, wave_name="canary",
        counts={"healthy": 1, "failed": 0, "pending": 2},
    )  # fmt: skip
    line = summary(fleet_with(rollout))
    assert line.startswith("0 robots: no robots; rollout: aaaaaaaaaaaa Progressing")
    assert "wave 1/3 (canary): 1 healthy, 0 failed, 2 pending" in line


def test_a_complete_rollout_or_none_is_not() -> None:
    done = RolloutStatus(revision="a" * 40, state="Complete", waves=3, wave_name="all")
    assert summary(fleet_with(done)) == "0 robots: no robots"
    assert summary(fleet_with(None)) == "0 robots: no robots"
