"""Text on a page, pure: `esc` is the one way text from a robot, a commit or a request reaches
a page; times as UTC text and as ages the page's script counts on; a list of facts."""

from __future__ import annotations

import html
import time

from robotconf.contract.textsafe import printable

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


def age(at: float | None, short: bool = False) -> str:
    """`<time data-since>`: the script shows its age and counts it on (`short`: the age alone,
    the time in its title, for a one-line summary). Without script, the time itself: the HTML
    of a box does not change as time passes, so only real changes are sent."""
    if at is None or not 0 <= at < 1e11:
        return "-"
    mark = " data-short" if short else ""
    return f'<time data-since="{at:.3f}"{mark}>{esc(when(at))}</time>'


def definitions(facts: list[tuple[str, str]]) -> str:
    """A `<dl>` of (name, already escaped HTML) pairs."""
    return "<dl>" + "".join(f"<dt>{name}</dt><dd>{value}</dd>" for name, value in facts) + "</dl>"


DIGEST_SHOWN = 8  # hex digits of a digest shown: not 12, the length a revision is shown at


def digest(value: str | None) -> str:
    """A launch request's digest, told apart from a git revision at a glance: labelled
    `sha256:`, 8 hex digits (a revision shows 12, as a link to its page), in a style of its own
    (`code.digest`), the whole digest in its title."""
    if not value:
        return "-"
    hexes = value.removeprefix("sha256:")
    return (
        f'<code class="digest" title="sha256:{esc(hexes, 80)}">'
        f"sha256:{esc(hexes[:DIGEST_SHOWN])}</code>"
    )


def fold(summary: str, details: str, opened: bool) -> str:
    """A box as one line, `summary`, with its `details` folded under it; `opened` when they
    say what is wrong. `data-fold` keeps the page's choice, for the script to keep a reader's
    own choice across live updates while the page's stays the same."""
    state = "open" if opened else "closed"
    return (
        f'<details data-fold="{state}"{" open" if opened else ""}>'
        f'<summary>{summary}</summary><div class="folded">{details}</div></details>'
    )
