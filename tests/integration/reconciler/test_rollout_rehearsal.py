"""The rollout guide's failure rehearsal, as written: under `robotconf up` (real agents, stand-in
brains, a real Mosquitto), the example fleet's commented `rollout:` block uncommented by the
guide's `sed`, then the guide's commit that makes the canary's brain crash. The rollout stops at
the canary wave, rolls it back, and `robotconf status` says so; no other robot moves."""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

from tests.integration.reconciler.test_rollout import complete
from tests.integration.reconciler.test_rollout_deaths import rolled_back
from tests.integration.reconciler.test_up import start_up
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for

GUIDE = Path(__file__).resolve().parents[3] / "docs" / "how-to" / "rollouts.md"
# The guide's two steps, verbatim (the test checks that the guide still says them).
POLICY = "sed -i -e 's/^# rollout:/rollout:/' -e 's/^#   /  /' configs/fleet.yaml"
CRASH = (
    'sed -i \'s/knowledge: {TARGET: {GOAL_ID: "2"}}/knowledge: {TARGET: {GOAL_ID: "2"}, '
    "STANDIN_CRASH: 3}/' configs/scenarios/delivery-gazebo.yaml"
)


def shell(lab: GitLab, command: str) -> None:
    subprocess.run(["bash", "-c", command], cwd=lab.root, check=True, timeout=30)


def desk_status(lab: GitLab) -> subprocess.CompletedProcess[str]:
    """`robotconf status` as the guide runs it: in the lab, no options (up's desk file)."""
    return subprocess.run(
        robotconf_argv("status"), cwd=lab.root, capture_output=True, text=True, timeout=60
    )


def test_the_guide_still_says_these_steps() -> None:
    text = GUIDE.read_text(encoding="utf-8")
    assert POLICY in text and CRASH in text


def test_a_crashing_canary_is_rolled_back_as_the_guide_says(
    tmp_path: Path, mosquitto: Mosquitto
) -> None:
    lab = GitLab(tmp_path / "lab")
    watch = FleetWatch(mosquitto.url)
    up = start_up(lab, tmp_path, "--broker", mosquitto.url)
    try:
        wait_for(lambda: "all robots InSync" in up.output(), "up to report InSync")
        shell(lab, POLICY)
        assert "\nrollout:\n" in lab.read("configs/fleet.yaml")
        stable = lab.commit("roll out in waves")  # no request changes: nothing moves
        watch.wait_reconciler(lambda s: complete(s, stable), "the policy applied")
        print(desk_status(lab).stdout)  # what the guide quotes
        before = lab.requests(stable)
        shell(lab, CRASH)
        bad = lab.commit("a brain that crashes")
        status = watch.wait_reconciler(lambda s: rolled_back(s, bad), "the canary rolled back")
        assert status.rollout is not None and status.rollout.failed == ["tb3-01"]
        assert "over max_failures 0" in status.message
        # tb3-01 (the canary, the only robot of delivery-gazebo) has the stable request back.
        watch.wait_running(before)
        done = desk_status(lab)
        print(done.stdout)  # what the guide quotes
        assert done.returncode == 1 and "RolledBack" in done.stdout
        assert "failed: tb3-01" in done.stdout
        log = (lab.root / ".robotconf" / "up" / "tb3-01" / "brain.log").read_text()
        assert "stand-in brain: crashing with code 3, as STANDIN_CRASH asks" in log
        print(log[-1500:])
    finally:
        code = up.stop(signal.SIGINT, timeout=60)
        watch.close()
    assert code == 0, up.output()
