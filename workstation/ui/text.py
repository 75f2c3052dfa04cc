"""Text on a page, pure: `esc` is the one way text from a robot, a commit or a request reaches
a page; times as UTC text and as ages the page's script counts on; a list of facts."""

from __future__ import annotations

import html
import time

from contract.textsafe import printable

MAX_TEXT = 500  # characters of one robot- or commit-supplied string shown


def esc(text: object, limit: int = MAX_TEXT) -> str:
    """The one way text from a robot, a commit or a request reaches a page: control characters
    written as escapes, cut at `limit`, then HTML-escaped (quotes too: safe in attributes)."""
    shown = printable(str(text))
    if len(shown) > limit:
        shown = shown[:limit] + "…"
    return html.escape(shown, quote=True)


def when(at: float | None) -> str:
    """A unix time as UTC text; `-` for none or nonsense (a robot's clock may say anything)."""
    if at is None or not 0 <= at < 1e11:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(at))


def age(at: float | None) -> str:
    """`<time data-since>`: the script shows its age and counts it on. Without script, the time
    itself: the HTML of a box does not change as time passes, so only real changes are sent."""
    if at is None or not 0 <= at < 1e11:
        return "-"
    return f'<time data-since="{at:.3f}">{esc(when(at))}</time>'


def definitions(facts: list[tuple[str, str]]) -> str:
    """A `<dl>` of (name, already escaped HTML) pairs."""
    return "<dl>" + "".join(f"<dt>{name}</dt><dd>{value}</dd>" for name, value in facts) + "</dl>"
