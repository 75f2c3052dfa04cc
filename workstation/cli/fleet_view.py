"""Fleet status for people: the reconciler's lines, then one table row per robot, worst first."""

from __future__ import annotations

from rich.console import Group
from rich.table import Table
from rich.text import Text

from robotconf.readmodel.verdicts import (
    FleetStatus,
    RobotRow,
    Verdict,
    reconciler_lines,
    short_digest,
)
from robotconf.workstation.cli.terminal import plain_text, safe

COLUMNS = (
    "ROBOT",
    "VERDICT",
    "ONLINE",
    "SCENARIO",
    "DESIRED",
    "REPORTED",
    "STATE",
    "RESTARTS",
    "RELOADS",
)
# Shown after SCENARIO when some robot has labels, or a rollout wave: a fleet without either
# keeps its table.
LABELS = "LABELS"
WAVE = "WAVE"
# Shown after RELOADS when some robot's agent publishes a goals summary: `done/failed` since its
# current request (`12/3`, `12/3 1 stale`), `unknown` when its brain does not report, `error`.
GOALS = "GOALS"
GOALS_LEGEND = (
    "goals: done/failed since each robot's current request (unknown: its brain does not report)"
)
# Shown last when some robot reports its interfaces: `ok`, `1 missing, 1 type`, `error`, ...
DRIFT = "DRIFT"
DRIFT_LINES = 20  # drift items listed under the table; the rest are counted

_STYLE = {
    Verdict.DEGRADED: "bold red",
    Verdict.UNKNOWN: "bold yellow",
    Verdict.OFFLINE: "red",
    Verdict.PROGRESSING: "yellow",
    Verdict.SUSPENDED: "blue",
    Verdict.UNASSIGNED: "dim",
    Verdict.IN_SYNC: "green",
}


def labels_text(labels: dict[str, str]) -> str:
    """`key=value,key=value` in key order, or "-"."""
    return ",".join(f"{key}={value}" for key, value in sorted(labels.items())) or "-"


def columns(rows: list[RobotRow]) -> tuple[str, ...]:
    extra = [
        name
        for name, shown in (
            (LABELS, any(r.labels for r in rows)),
            (WAVE, any(r.wave for r in rows)),
        )
        if shown
    ]
    at = COLUMNS.index("SCENARIO") + 1
    goals = (GOALS,) if any(r.goals.published for r in rows) else ()
    drift = (DRIFT,) if any(r.drift.interfaces != "unknown" for r in rows) else ()
    return (*COLUMNS[:at], *extra, *COLUMNS[at:], *goals, *drift)


def fleet_table(fleet: FleetStatus) -> Table:
    # No box and no edge padding: in plain text each row starts with its robot id.
    table = Table(box=None, pad_edge=False, show_edge=False, header_style="bold")
    names = columns(fleet.rows)
    for name in names:
        table.add_column(name, no_wrap=name not in ("SCENARIO", LABELS))
    table.add_column("", overflow="fold")  # why a robot is not in sync: wraps on a terminal
    for r in fleet.rows:
        style = _STYLE[r.verdict]
        # Labels are text from fleet.yaml: safe() escapes them and never reads them as markup.
        labels = [safe(labels_text(r.labels))] if LABELS in names else []
        if WAVE in names:
            labels.append(safe(r.wave or "-"))
        table.add_row(
            safe(r.robot_id),
            Text(r.verdict.value, style=style),
            Text("yes" if r.online else "no"),
            safe(r.scenario or "-"),
            *labels,
            Text(short_digest(r.desired)),
            Text(short_digest(r.reported)),
            safe(r.state),
            Text(str(r.restarts)),
            Text(str(r.reloads)),
            *([_goals_cell(r)] if GOALS in names else []),
            *([_drift_cell(r)] if DRIFT in names else []),
            safe("" if r.verdict is Verdict.IN_SYNC else r.reason),
        )
    return table


def _goals_cell(row: RobotRow) -> Text:
    goals = row.goals
    style = "red" if goals.failing else "yellow" if goals.unreadable else ""
    return Text(goals.cell(), style=style)


def _drift_cell(row: RobotRow) -> Text:
    summary = row.drift.summary()
    style = "red" if row.drift.drifted else "yellow" if summary in ("error", "ok?") else ""
    return Text(summary, style=style)


def drift_lines(rows: list[RobotRow], limit: int = DRIFT_LINES) -> list[str]:
    """`drift: tb3-04 lacks /scan (...)`, worst first as the rows are; notes after the items."""
    lines = [f"drift: {item.text()}" for r in rows for item in r.drift.items]
    lines += [f"note: {r.robot_id}: {r.drift.note}" for r in rows if r.drift.note]
    if len(lines) > limit:
        lines = [*lines[:limit], f"... {len(lines) - limit} more (robotconf status --json)"]
    return lines


def fleet_status_view(fleet: FleetStatus) -> Group:
    """The whole report as rich renderables (for a terminal or a live screen)."""
    lines = reconciler_lines(fleet.reconciler, fleet.checked_at)
    lines.append(f"desired: {fleet.desired_from}")
    if fleet.lost is not None:
        lines.append(f"warning: {fleet.lost}")
    lines += [f"note: {n}" for n in fleet.notes]
    if fleet.ignored:
        kinds = ", ".join(f"{n} {kind}" for kind, n in sorted(fleet.ignored.items()))
        lines.append(f"note: unreadable retained payloads skipped: {kinds}")
    parts: list[Table | Text] = [safe(line) for line in lines]
    parts.append(Text(""))
    if fleet.rows:
        parts.append(fleet_table(fleet))
        if any(r.goals.published for r in fleet.rows):
            parts.append(Text(GOALS_LEGEND, style="dim"))
    else:
        parts.append(Text("  ".join(COLUMNS)))
        parts.append(Text("(no robot is assigned or known to the broker)"))
    warnings = [f"warning: {r.robot_id}: {w}" for r in fleet.rows for w in r.warnings]
    if warnings:
        parts.append(Text(""))
        parts += [safe(w, "yellow") for w in warnings]
    drifted = drift_lines(fleet.rows)
    if drifted:
        parts.append(Text(""))
        parts += [safe(line, "red" if line.startswith("drift:") else "yellow") for line in drifted]
    restarts = [line for r in fleet.rows if (line := r.restart_line()) is not None]
    if restarts:
        parts.append(Text(""))
        parts += [safe(line) for line in restarts]
    counts = ", ".join(f"{n} {v}" for v, n in fleet.counts().items()) or "no robots"
    parts.append(Text(""))
    why = fleet.not_in_sync_because()
    parts.append(
        safe(f"{len(fleet.rows)} robots: {counts}" + (f" — not in sync: {why}" if why else ""))
    )
    return Group(*parts)


def fleet_status_text(fleet: FleetStatus) -> str:
    """The report as plain text: what pipes, files and tests see."""
    return plain_text(fleet_status_view(fleet))
