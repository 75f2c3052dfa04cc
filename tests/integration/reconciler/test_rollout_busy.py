"""A busy canary, end to end: its brain's hold file holds off the new request past the wave's
timeout, and the rollout waits for it (pending, never failed) until it is released."""

from __future__ import annotations

import time
from pathlib import Path

from robotconf.contract.wire import AgentState
from tests.integration.reconciler.conftest import Fleet
from tests.integration.reconciler.test_rollout import CANARY, complete, rename_all, with_policy

WAVE_TIMEOUT = 2.0


def test_a_deferring_canary_is_pending_past_the_wave_timeout_then_rolls_on(
    fleet: Fleet, tmp_path: Path
) -> None:
    with_policy(
        fleet,
        "rollout:\n  waves: [{name: canary, selector: {ring: canary}}, {name: all}]\n"
        f"  healthy_after: 0.5\n  max_failures: 0\n  wave_timeout: {WAVE_TIMEOUT}\n"
        "  on_failure: rollback\n",
    )
    hold = tmp_path / "agents" / CANARY / "brain.hold"  # $ROBOTCONF_HOLD_FILE of its brain
    hold.touch()  # the canary's brain is mid-task: "not now"
    head = rename_all(fleet, "busy")
    busy = fleet.watch.wait_for(
        CANARY, lambda s: s.state is AgentState.DEFERRED, "the canary to defer"
    )
    assert busy.deferred_since is not None
    # Its wave's timeout passes twice over while it defers (its max_defer is 300 s).
    until = time.monotonic() + 2 * WAVE_TIMEOUT + 1
    while time.monotonic() < until:
        time.sleep(0.2)
    status = fleet.watch.reconciler()
    assert status is not None and status.rollout is not None
    assert (status.rollout.state, status.rollout.wave_name) == ("Progressing", "canary")
    assert status.rollout.pending == [CANARY] and status.rollout.failed == []
    assert fleet.watch.status(CANARY).state is AgentState.DEFERRED  # type: ignore[union-attr]
    text = fleet.status_cli().stdout
    assert "deferred" in text and "deferred by the brain's hold file since" in text
    hold.unlink()  # task done
    fleet.watch.wait_reconciler(lambda s: complete(s, head), "the rollout complete")
    fleet.watch.wait_running(fleet.requests(head))
