"""Fleets for the UI's pure tests: rows and snapshots made directly, no broker."""

from __future__ import annotations

from dataclasses import replace

from robotconf.contract.wire import ReconcilerStatus, StatusDiagnostic
from robotconf.readmodel.verdicts import WORST_FIRST, FleetStatus, RobotRow, Verdict
from robotconf.workstation.ui.model import Snapshot

D1 = "sha256:" + "1" * 64
D2 = "sha256:" + "2" * 64
NOW = 1_790_000_000.0


def row(robot_id: str, verdict: Verdict = Verdict.IN_SYNC, **fields: object) -> RobotRow:
    made = RobotRow(
        robot_id=robot_id,
        verdict=verdict,
        reason="running the desired request" if verdict is Verdict.IN_SYNC else "starting",
        online=True,
        scenario="delivery",
        desired=D1,
        published=D1,
        reported=D1 if verdict is Verdict.IN_SYNC else D2,
        state="running" if verdict is Verdict.IN_SYNC else "starting",
        restarts=0,
    )
    return replace(made, **fields)  # type: ignore[arg-type]


def reconciler(**fields: object) -> ReconcilerStatus:
    status = ReconcilerStatus(
        state="Ready",
        ready=True,
        reason="Applied",
        branch="main",
        last_applied_revision="a" * 40,
        heartbeat=NOW,
        interval=30.0,
    )
    return status.model_copy(update=fields)


def refused() -> ReconcilerStatus:
    return reconciler(
        state="Stalled",
        ready=False,
        reason="BuildFailed",
        failed_revision="b" * 40,
        diagnostics=[
            StatusDiagnostic(
                path="configs/fleet.yaml",
                line=3,
                column=5,
                code="RC101",
                message="no such scenario",
            ),
            StatusDiagnostic(code="SourceUnavailable", message="<b>not bold</b>"),
        ],
    )


def fleet(rows: list[RobotRow], status: ReconcilerStatus | None = None) -> FleetStatus:
    ordered = sorted(
        rows, key=lambda r: (WORST_FIRST.index(r.verdict), not r.drift.drifted, r.robot_id)
    )
    return FleetStatus(
        ordered, status if status is not None else reconciler(), "a repo", checked_at=NOW
    )


def snapshot(fleet: FleetStatus | None, version: int = 1, connected: bool = True) -> Snapshot:
    by_id = {r.robot_id: r for r in fleet.rows} if fleet is not None else {}
    error = None if connected else "connection refused"
    return Snapshot(version, fleet, "mqtt://127.0.0.1:1883", connected, error, NOW, {}, by_id)
