"""`robotconf history` (a real process) on a real ledger: what a revision achieved beside the one
before, narrowed by robot and time, as text and JSON; every refusal one line."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.readmodel.ledger import Ledger, ledger_path
from tests.support.fleet import robotconf_argv

OLD, NEW = "0a" * 20, "0b" * 20


def record(seq: int, revision: str, robot: str, outcome: OutcomeState, task: str) -> OutcomeRecord:
    return OutcomeRecord(
        robot_id=robot,
        revision=revision,
        digest=None,
        scenario="delivery-gazebo",
        run="run-1",
        seq=seq,
        goal=f"g{seq}",
        task=task,
        outcome=outcome,
        code="NAV2_TIMEOUT" if outcome is OutcomeState.FAILED else None,
        ended_at=time.time() - (3 * 3600 if seq < 10 else 0),
        duration=5.0,
    )


@pytest.fixture
def state(tmp_path: Path) -> Path:
    with Ledger.open_or_start(ledger_path(tmp_path)) as ledger:
        S, F = OutcomeState.SUCCEEDED, OutcomeState.FAILED
        ledger.add([record(i, OLD, "tb3-01", S, "Deliver") for i in range(10)], time.time() - 60)
        ledger.add(
            [
                record(10 + i, NEW, f"tb3-0{1 + i % 2}", F if i % 2 else S, "Deliver")
                for i in range(8)
            ]
            + [record(30, NEW, "tb3-01", S, "Dock")]
        )
    return tmp_path


def history(state: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        robotconf_argv("history", "--state-dir", str(state), *args),
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_the_newest_revision_beside_the_one_before(state: Path) -> None:
    shown = history(state)
    assert shown.returncode == 0, shown.stderr
    lines = shown.stdout.splitlines()
    assert lines[1].startswith(f"revision {NEW[:12]}") and f"beside {OLD[:12]}" in lines[1]
    rows = {line.split()[0]: line.split() for line in lines[2:] if line.strip()}
    # succeeded failed canceled stale success before mean
    assert rows["all"][1:7] == ["5", "4", "0", "0", "56%", "100%"]
    assert rows["Deliver"][1:7] == ["4", "4", "0", "0", "50%", "100%"]
    assert rows["Dock"][5:7] == ["100%", "-"]
    assert "failure codes: NAV2_TIMEOUT 4" in shown.stdout
    assert rows["tb3-02"][1:6] == ["0", "4", "0", "0", "0%"]  # the worst robot first


def test_narrowed_by_revision_robot_and_time_as_json(state: Path) -> None:
    shown = history(state, "--rev", OLD[:6], "--json")
    found = json.loads(shown.stdout)
    assert found["revision"]["revision"] == OLD and found["before"] is None
    assert found["revision"]["total"] == 10
    shown = history(state, "--robot", "tb3-02", "--since", "1h", "--json")
    found = json.loads(shown.stdout)
    assert found["robot"] == "tb3-02" and found["revision"]["failed"] == 4
    assert found["before"]["total"] == 0  # its old outcomes ended 3 hours ago
    changes = {(c["scenario"], c["task"]): c for c in found["changes"]}
    assert changes[("delivery-gazebo", "Deliver")]["success_rate"] == 0.0


def test_nothing_that_matches_exits_1(state: Path) -> None:
    shown = history(state, "--robot", "tb3-99")
    assert shown.returncode == 1 and "no goal outcomes match" in shown.stdout


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (("--rev", "ffff"), "no outcomes of a revision 'ffff'"),
        (("--rev", "0"), "at least 4 characters"),
        (("--since", "soon"), "--since: 'soon' is not a duration"),
    ],
)
def test_refusals_are_one_line(state: Path, args: tuple[str, ...], said: str) -> None:
    shown = history(state, *args)
    assert shown.returncode == 2 and said in shown.stderr
    assert shown.stderr.count("\n") == 1 and "Traceback" not in shown.stderr
