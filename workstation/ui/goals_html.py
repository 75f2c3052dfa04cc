"""What robots achieve, as HTML, pure: a robot's goals box (the goal underway with a progress bar,
counts per task, recent outcomes with their codes, vitals and events), the fleet's goals cell,
and the fleet page's success rate per scenario and revision. Every robot-supplied string goes
through `esc`; the progress bar is a `<progress>` element (the CSP forbids inline styles)."""

from __future__ import annotations

from urllib.parse import quote

from robotconf.contract.goals import BrainEvent, CurrentGoal, GoalsSummary, LastOutcome, VitalValue
from robotconf.contract.textsafe import shorten
from robotconf.contract.wire import ReconcilerStatus
from robotconf.readmodel.robot_goals import COUNTS, GoalRate, goal_rates
from robotconf.readmodel.verdicts import SUBJECT_SHOWN, RobotRow, short_rev
from robotconf.workstation.ui.model import FleetQuery, Snapshot
from robotconf.workstation.ui.text import age, definitions, digest, esc, fold

RATES_SHOWN = 50  # (scenario, revision) rows of the fleet page's success rates; the rest counted
# More (scenario, revision) rows than this and the rates fold to one line: the robots' table,
# where trouble shows, stays in the first screen of a large fleet.
RATES_OPEN = 3
HEADINGS = {"completed": "Succeeded"}  # the counts' names as a table heads them


def goals_cell(row: RobotRow) -> str:
    """The fleet table's Goals cell: `done/failed`, `unknown` or `error` as text."""
    goals = row.goals
    failing = " failing" if goals.failing else ""
    return f'<td class="goals{failing}" data-goals="{goals.state}">{esc(goals.cell(), 40)}</td>'


def duration(seconds: float | None) -> str:
    """`42 s`, `3 min 5 s`, `2 h 4 min`; `-` for none or nonsense."""
    if seconds is None or not 0 <= seconds < 1e9:
        return "-"
    whole = round(seconds)
    if whole < 120:
        return f"{seconds:.1f} s" if seconds < 10 else f"{whole} s"
    if whole < 7200:
        return f"{whole // 60} min {whole % 60} s"
    return f"{whole // 3600} h {whole % 3600 // 60} min"


def percent(fraction: float | None) -> str:
    return "-" if fraction is None else f"{100 * fraction:.0f}%"


# ------------------------------------------------------------------ a robot's page


def goals_box(snap: Snapshot, robot_id: str) -> str:
    """A robot's live goals box: what its brain achieved since its current request."""
    row = snap.row(robot_id)
    goals = row.goals if row is not None else None
    if goals is None or not goals.known or goals.summary is None:
        state = goals.state if goals is not None else "unknown"
        note = goals.note if goals is not None and goals.note else "not known to the broker"
        return (
            f'<section data-box="goals" data-goals="{state}"><h2>Goals</h2>'
            f"<p>Goals {state}: {esc(note)}.</p></section>"
        )
    s = goals.summary
    return (
        f'<section data-box="goals" data-goals="{goals.state}"><h2>Goals</h2>'
        f"{counts_line(s)}{definitions(run_facts(s))}{current_goal(s.current)}"
        f"{task_table(s)}{outcome_table(s.recent)}{vitals_list(s.vitals, s.vitals_at)}"
        f"{event_list(s.events)}</section>"
    )


def counts_line(s: GoalsSummary) -> str:
    return (
        f'<p data-goal-counts="{s.completed}/{s.failed}">Since its current request: '
        f"<strong>{s.completed} succeeded</strong>, <strong>{s.failed} failed</strong>, "
        f"{s.canceled} canceled, {s.stale} stale, {s.underway} underway.</p>"
    )


def run_facts(s: GoalsSummary) -> list[tuple[str, str]]:
    ready = "yes" if s.ready else "not yet" if s.ready is False else "-"
    found = [
        ("Revision", revision_link(s.revision)),
        ("Digest", digest(s.digest)),
        ("Scenario", esc(s.scenario or "-")),
        ("Counted since", age(s.since)),
        ("Brain run", f"<code>{esc(s.run or '-', 80)}</code>"),
        ("Ready", ready),
        ("Updated", age(s.updated)),
    ]
    if s.dropped:
        found.append(("Dropped", f"{s.dropped} lines refused or throttled"))
    return found


def current_goal(goal: CurrentGoal | None) -> str:
    """The goal underway: its task, a progress bar (indeterminate without a fraction), ETA and
    note; marked stale when its agent saw no progress for its stale time."""
    if goal is None:
        return '<div data-current-goal="none"><h3>Current goal</h3><p>None underway.</p></div>'
    label = f"progress of {esc(goal.task, 128)}"
    value = f' value="{goal.fraction:.4f}"' if goal.fraction is not None else ""
    bar = f'<progress max="1"{value} aria-label="{label}">{percent(goal.fraction)}</progress>'
    eta = f", about {duration(goal.eta)} left" if goal.eta is not None else ""
    note = f' <span class="note">{esc(goal.note)}</span>' if goal.note else ""
    stale = (
        ' <strong class="stale">stale: no progress for its agent\'s stale time</strong>'
        if goal.stale
        else ""
    )
    return (
        f'<div data-current-goal="{esc(goal.goal, 128)}"{" data-stale" if goal.stale else ""}>'
        f"<h3>Current goal</h3><p>Task <strong>{esc(goal.task, 128)}</strong> "
        f"(goal <code>{esc(goal.goal, 128)}</code>), started {age(goal.started_at)}, "
        f"last heard {age(goal.updated_at)}{stale}</p>"
        f'<p class="progress">{bar} <span data-percent>{percent(goal.fraction)}</span>{eta}'
        f"{note}</p></div>"
    )


def task_table(s: GoalsSummary) -> str:
    if not s.tasks:
        return ""
    head = "".join(
        f'<th scope="col">{HEADINGS.get(name, name.capitalize())}</th>' for name in COUNTS
    )
    rows = "".join(
        f'<tr data-task="{esc(task, 128)}"><th scope="row">{esc(task, 128)}</th>'
        + "".join(f"<td>{getattr(counts, name)}</td>" for name in COUNTS)
        + "</tr>"
        for task, counts in s.tasks.items()
    )
    return (
        '<h3>Per task</h3><div class="scroll"><table data-tasks><thead><tr>'
        f'<th scope="col">Task</th>{head}</tr></thead><tbody>{rows}</tbody></table></div>'
    )


def outcome_table(recent: list[LastOutcome]) -> str:
    """Recent ended goals, newest first, with their codes and messages."""
    if not recent:
        return "<h3>Recent outcomes</h3><p>No goal has ended since its current request.</p>"
    rows = "".join(
        f'<tr data-outcome="{o.outcome.value}"><td>{age(o.ended_at)}</td>'
        f"<td>{esc(o.task, 128)}</td><td><code>{esc(o.goal, 128)}</code></td>"
        f'<td><span class="outcome">{o.outcome.value}</span></td>'
        f"<td><code>{esc(o.code or '-', 64)}</code></td><td>{esc(o.message or '')}</td>"
        f"<td>{duration(o.duration)}</td></tr>"
        for o in reversed(recent)
    )
    return (
        '<h3>Recent outcomes</h3><div class="scroll"><table data-outcomes><thead><tr>'
        '<th scope="col">Ended</th><th scope="col">Task</th><th scope="col">Goal</th>'
        '<th scope="col">Outcome</th><th scope="col">Code</th><th scope="col">Message</th>'
        f'<th scope="col">Took</th></tr></thead><tbody>{rows}</tbody></table></div>'
    )


def vital_text(value: VitalValue) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    return esc(value)


def vitals_list(vitals: dict[str, VitalValue], at: float | None) -> str:
    if not vitals:
        return ""
    items = "".join(
        f'<dt>{esc(name, 32)}</dt><dd data-vital="{esc(name, 32)}">{vital_text(value)}</dd>'
        for name, value in vitals.items()
    )
    return f"<h3>Vitals</h3><p>Reported {age(at)}</p><dl data-vitals>{items}</dl>"


def event_list(events: list[BrainEvent]) -> str:
    if not events:
        return ""
    items = "".join(
        f'<li data-severity="{e.severity.value}">{age(e.at)} '
        f'<strong class="severity">{e.severity.value}</strong> {esc(e.message)}</li>'
        for e in reversed(events)
    )
    return f"<h3>Events</h3><ul data-brain-events>{items}</ul>"


# ------------------------------------------------------------------ the fleet page


def rates_box(snap: Snapshot, query: FleetQuery) -> str:
    """The success rate per scenario and revision of the robots the page's query selects
    (its verdict aside), from their goals since their current requests."""
    fleet = snap.fleet
    if fleet is None:
        return '<section data-box="rates" hidden></section>'
    rates, silent = goal_rates((row.scenario, row.goals) for row in fleet.rows if query.wants(row))
    if not rates:
        return '<section data-box="rates" hidden></section>'
    shown = "".join(rate_row(rate) for rate in rates[:RATES_SHOWN])
    more = (
        f"<p>… {len(rates) - RATES_SHOWN} more scenario and revision pairs.</p>"
        if len(rates) > RATES_SHOWN
        else ""
    )
    quiet = f"<p>{silent} robots do not report their goals (unknown).</p>" if silent else ""
    details = (
        "<p>Goals ended since each robot's current request; the rate is succeeded of succeeded "
        'and failed (canceled and stale goals are not counted against it).</p><div class="scroll">'
        '<table data-rates><thead><tr><th scope="col">Scenario</th><th scope="col">Revision</th>'
        '<th scope="col">Robots</th><th scope="col">Success rate</th>'
        '<th scope="col">Succeeded</th><th scope="col">Failed</th><th scope="col">Canceled</th>'
        '<th scope="col">Stale</th><th scope="col">Underway</th></tr></thead>'
        f"<tbody>{shown}</tbody></table></div>{more}{quiet}"
    )
    line = (
        "<h2>Goals: success rate per scenario and revision</h2> "
        f'<span class="line">{rates_line(rates)}</span>'
    )
    return f'<section data-box="rates">{fold(line, details, len(rates) <= RATES_OPEN)}</section>'


def rates_line(rates: list[GoalRate]) -> str:
    """The rates in a few words: how many pairs, and the lowest rate."""
    pairs = f"{len(rates)} scenario and revision pair{'' if len(rates) == 1 else 's'}"
    rated = [r for r in rates if r.rate is not None]
    if not rated:
        return f"{pairs}, no goal ended yet"
    low = min(rated, key=lambda r: (r.rate or 0.0, r.scenario or ""))
    return (
        f"{pairs}, lowest {low.rate_text()}: {esc(low.scenario or '-', 128)} at "
        f"{revision_link(low.revision)}"
    )


def revision_link(revision: str | None, status: ReconcilerStatus | None = None) -> str:
    """A revision, linked to its page; its commit's subject beside it when the reconciler's
    status carries it (commit text is data: escaped, shortened)."""
    if not revision:
        return "-"
    line = status.commit(revision) if status is not None else None
    subject = (
        f' <span class="subject">{esc(shorten(line.subject, SUBJECT_SHOWN))}</span>'
        if line is not None and line.subject
        else ""
    )
    return (
        f'<a class="rev" href="/revisions/{quote(revision, safe="")}" '
        f'title="commit {esc(revision, 80)}"><code>{esc(short_rev(revision))}</code></a>'
        f"{subject}"
    )


def rate_row(rate: GoalRate) -> str:
    return (
        f'<tr data-scenario="{esc(rate.scenario or "-", 128)}" '
        f'data-revision="{esc(rate.revision or "-", 80)}" data-rate="{rate.rate_text()}">'
        f'<th scope="row">{esc(rate.scenario or "-", 128)}</th>'
        f"<td>{revision_link(rate.revision)}</td><td>{rate.robots}</td>"
        f"<td><strong>{rate.rate_text()}</strong></td><td>{rate.completed}</td>"
        f"<td>{rate.failed}</td><td>{rate.canceled}</td><td>{rate.stale}</td>"
        f"<td>{rate.underway}</td></tr>"
    )
