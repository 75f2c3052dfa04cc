"""`robotconf history`: what a revision achieved, beside the revision before it, from the
reconciler's outcome ledger (per scenario and task, per robot; read-only, never the broker)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from robotconf.contract.durations import parse_duration
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.textsafe import printable
from robotconf.contract.wire import short_rev
from robotconf.readmodel.ledger import Ledger, LedgerError, find_ledger
from robotconf.readmodel.outcomes import History, RevisionReport, Tally
from robotconf.workstation.cli.broker_options import prefix_option
from robotconf.workstation.cli.options import ledger_dir_option, repo_option

ROBOTS_SHOWN = 10  # robots listed in the text form, worst first (--json: all)


@click.command("history")
@repo_option
@prefix_option
@ledger_dir_option
@click.option(
    "--rev", default=None, help="this revision (or its first characters); default: the newest"
)
@click.option("--robot", default=None, metavar="ID", help="only this robot's outcomes")
@click.option(
    "--since",
    default=None,
    metavar="DURATION",
    help="only goals that ended in this last while (e.g. 30m, 2h, 7d)",
)
@click.option("--json", "as_json", is_flag=True, help="machine-readable output")
def history(
    repo: Path,
    prefix: str,
    state_dir: Path | None,
    rev: str | None,
    robot: str | None,
    since: str | None,
    as_json: bool,
) -> ExitCode:
    """What a revision's robots achieved (goals succeeded, failed, canceled, gone stale, per
    scenario and task, and per robot) beside the revision before it, from the outcome ledger
    the reconciler keeps; exits 1 when the ledger holds no outcome that matches."""
    try:
        after = time.time() - parse_duration(since, clamp=True) if since is not None else None
    except ValueError as exc:
        raise CliError(f"--since: {exc}") from None
    path = find_ledger(repo, prefix, state_dir)
    try:
        with Ledger.open(path, read_only=True, check=False) as ledger:
            found = ledger.history(rev, robot=robot, since=after)
    except LedgerError as exc:
        raise CliError(str(exc)) from None
    if as_json:
        click.echo(json.dumps({"ledger": str(path), **found.as_json()}, indent=2))
    else:
        click.echo("\n".join(text(found, path)))
    return ExitCode.OK if found.report.tally.total else ExitCode.FINDINGS


def text(found: History, path: Path) -> list[str]:
    """The history as lines: a heading, the table of scenarios and tasks, the worst robots."""
    report, before = found.report, found.before
    narrowed = []
    if found.robot is not None:
        narrowed.append(f"robot {printable(found.robot)}")
    if found.since is not None:
        narrowed.append(f"goals ended since {_when(found.since)}")
    lines = [
        f"ledger: {path}",
        f"revision {short_rev(report.revision)}{_seen(report)}"
        + (
            f", beside {short_rev(before.revision)}{_seen(before)}"
            if before
            else ", the first seen"
        )
        + (f" ({', '.join(narrowed)})" if narrowed else ""),
    ]
    if not report.tally.total:
        lines.append("no goal outcomes match")
        return lines
    header = ("", "succeeded", "failed", "canceled", "stale", "success", "before", "mean s")
    rows: list[tuple[str, ...]] = [header]
    rows.append(_row("all", report.tally, before.tally if before else None))
    old = before.scenarios if before is not None else {}
    for name, scenario in report.scenarios.items():
        was = old.get(name)
        rows.append(_row(printable(name), scenario.tally, was.tally if was else None))
        for task, tally in scenario.tasks.items():
            then = was.tasks.get(task) if was is not None else None
            rows.append(_row(f"  {printable(task)}", tally, then))
    lines += _table(rows)
    if report.codes:
        codes = ", ".join(f"{printable(code)} {count}" for code, count in report.codes.items())
        lines.append(f"failure codes: {codes}")
    if found.robot is None and report.robots:
        worst = report.worst_robots(ROBOTS_SHOWN)
        lines.append(f"robots, lowest success first ({len(worst)} of {len(report.robots)}):")
        robot_rows: list[tuple[str, ...]] = [header[:6]]
        old_robots = before.robots if before is not None else {}
        robot_rows += [
            _row(f"  {printable(robot)}", tally, old_robots.get(robot))[:6]
            for robot, tally in worst
        ]
        lines += _table(robot_rows)
    return lines


def _row(name: str, tally: Tally, before: Tally | None) -> tuple[str, ...]:
    mean = tally.mean_duration
    return (
        name,
        str(tally.succeeded),
        str(tally.failed),
        str(tally.canceled),
        str(tally.stale),
        _percent(tally.success_rate),
        _percent(before.success_rate) if before is not None else "-",
        "-" if mean is None else f"{mean:.1f}",
    )


def _percent(rate: float | None) -> str:
    return "-" if rate is None else f"{rate * 100:.0f}%"


def _table(rows: list[tuple[str, ...]]) -> list[str]:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return [
        "  ".join(
            cell.ljust(width) if i == 0 else cell.rjust(width)
            for i, (cell, width) in enumerate(zip(row, widths, strict=True))
        ).rstrip()
        for row in rows
    ]


def _seen(report: RevisionReport) -> str:
    if report.first_seen is None or report.last_seen is None:
        return ""
    first, last = _when(report.first_seen), _when(report.last_seen)
    if first[:10] == last[:10]:  # the same day: its time only
        last = last[11:]
    return f" (outcomes {first} to {last})"


def _when(at: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(at))
