"""The timeline page (/timeline), pure: the fleet's events kept in the reconciler's ledger,
newest first, with a form that narrows them by robot and kind (the query string carries it,
so a filtered view is a link). Every string from the ledger goes through `esc`, cut."""

from __future__ import annotations

from collections.abc import Sequence
from urllib.parse import parse_qsl, quote

from robotconf.readmodel.timeline import KINDS, EventQuery, KeptEvent, QueryRefused, event_query
from robotconf.workstation.ui.auth import Identity
from robotconf.workstation.ui.goals_html import revision_link
from robotconf.workstation.ui.pages import page
from robotconf.workstation.ui.text import esc, when

MAX_QUERY = 1024  # characters of the page's query string (three short fields)
MAX_FIELDS = 8
SHOWN = 500  # events listed at most, the newest
_FIELDS = ("robot", "kind", "since")


def timeline_query(query: str, now: float) -> tuple[EventQuery, dict[str, str]]:
    """The page's filter from its query string, and its fields as typed (shown back in the
    form); QueryRefused (a 400 page) when it is too long or a field is not a robot id, an
    event kind or a duration. Other fields are ignored."""
    if len(query) > MAX_QUERY:
        raise QueryRefused(f"the query is {len(query):,} characters, over {MAX_QUERY:,}")
    try:
        fields = parse_qsl(query, keep_blank_values=True, max_num_fields=MAX_FIELDS)
    except ValueError:
        raise QueryRefused(f"the query has more than {MAX_FIELDS} fields") from None
    found = {name: value for name, value in fields if name in _FIELDS}
    asked = event_query(
        found.get("robot"), found.get("kind"), found.get("since"), now=now, limit=SHOWN
    )
    return asked, found


def timeline_page(
    query: EventQuery,
    typed: dict[str, str],
    who: Identity,
    events: Sequence[KeptEvent] | None,
    why: str | None = None,
) -> str:
    """`events`: the ledger's answer (None: `why` it could not be asked); `typed`: the form's
    fields as the person gave them, shown back."""
    if events is None:
        listing = f'<p data-timeline="unavailable">{esc(why or "The ledger is not open here.")}</p>'
    elif not events:
        listing = '<p data-timeline="empty">No event matches.</p>'
    else:
        rows = "".join(_row(event) for event in events)
        more = (
            f"<p>The newest {len(events)} are shown; narrow by robot, kind or time for older.</p>"
            if len(events) >= query.limit
            else ""
        )
        listing = (
            '<div class="scroll"><table data-timeline="kept"><thead><tr>'
            '<th scope="col">When</th><th scope="col">Kind</th><th scope="col">Robot</th>'
            '<th scope="col">Revision</th><th scope="col">What happened</th></tr></thead>'
            f"<tbody>{rows}</tbody></table></div>{more}"
        )
    body = (
        "<div data-timeline-page><h1>Timeline</h1><p>What happened to the fleet, newest first, "
        "as the reconciler keeps it in its ledger (bounded by --ledger-max-age).</p>"
        + _form(typed)
        + listing
        + "</div>"
    )
    return page("Timeline", body, who)


def _form(typed: dict[str, str]) -> str:
    kind = typed.get("kind", "")
    options = '<option value="">any kind</option>' + "".join(
        f'<option value="{k}"{" selected" if k == kind else ""}>{k}</option>' for k in KINDS
    )
    return (
        '<form method="get" action="/timeline" data-timeline-filter>'
        '<label>Robot <input name="robot" maxlength="64" '
        f'value="{esc(typed.get("robot", ""), 64)}"></label> '
        f'<label>Kind <select name="kind">{options}</select></label> '
        '<label>Since <input name="since" maxlength="32" placeholder="e.g. 2h, 7d" '
        f'value="{esc(typed.get("since", ""), 32)}"></label> '
        '<button type="submit">Show</button> <a href="/timeline">all</a></form>'
    )


def _row(event: KeptEvent) -> str:
    robot = (
        f'<a href="/robots/{quote(event.robot, safe="")}">{esc(event.robot, 64)}</a>'
        if event.robot
        else "-"
    )
    who = f" <span data-by>by {esc(event.by, 64)}</span>" if event.by else ""
    subject = f' <span class="subject">{esc(event.subject, 100)}</span>' if event.subject else ""
    return (
        f'<tr data-event="{esc(event.kind, 64)}" data-robot="{esc(event.robot or "", 64)}">'
        f"<td>{esc(when(event.at))}</td><td><code>{esc(event.kind, 64)}</code></td>"
        f"<td>{robot}</td><td>{revision_link(event.revision)}{subject}</td>"
        f"<td>{esc(event.message, 600)}{who}</td></tr>"
    )
