"""The operator's page parts, pure: the login form, the restart confirmation, a restart's
outcome. Every string that came from outside goes through the pages' `esc`."""

from __future__ import annotations

import re
import time
from urllib.parse import quote

from robotconf.workstation.ui.auth import Identity
from robotconf.workstation.ui.operators import MAX_NAME
from robotconf.workstation.ui.restarts import Outcome
from robotconf.workstation.ui.rollout_decisions import Decision
from robotconf.workstation.ui.text import esc

MAX_NEXT = 512
# A path on this site, with a query perhaps: no scheme, no host (`//evil`), no backslash that
# a browser would read as a slash, nothing outside visible ASCII.
_LOCAL_PATH = re.compile(r"/(?![/\\])[A-Za-z0-9._~!$&'()*+,;=:@%/?-]*")


def local_path(candidate: str | None) -> str:
    """`candidate` when it is a path on this site, else "/": a login never sends anyone
    elsewhere."""
    if candidate and len(candidate) <= MAX_NEXT and _LOCAL_PATH.fullmatch(candidate):
        return candidate
    return "/"


def login_form(
    next_path: str, message: str = "", *, enabled: bool = True, named: bool = False
) -> str:
    """The login form (`form[data-login]`, its fields `username` and `token`): the name is
    asked for when operators are named (--operators-file), else a fixed one for password
    managers and screen readers (a password field has its user name)."""
    if not enabled:
        return (
            "<h1>Log in</h1><p data-login-disabled>This UI was started without "
            "<code>--operator-token-file</code> or <code>--operators-file</code>: it is "
            "read-only, nobody logs in.</p>"
        )
    said = f'<p class="refusal" role="alert">{esc(message)}</p>' if message else ""
    name = (
        '<label for="username">Operator name</label> '
        '<input type="text" id="username" name="username" autocomplete="username" '
        f'required maxlength="{MAX_NAME}" autofocus> '
        if named
        else '<input type="text" name="username" value="operator" autocomplete="username" hidden>'
    )
    return (
        f"<h1>Log in as an operator</h1>{said}"
        '<form method="post" action="/login" data-login>'
        f"{name}"
        '<label for="token">Operator token</label> '
        '<input type="password" id="token" name="token" autocomplete="current-password" '
        f'required maxlength="1024"{"" if named else " autofocus"}> '
        f'<input type="hidden" name="next" value="{esc(local_path(next_path))}">'
        '<button type="submit">Log in</button></form>'
        "<p>Operators may restart robots and read their brains' logs; "
        "anyone who can open this page may look.</p>"
    )


def logged_in(name: str = "") -> str:
    who = f"the operator {esc(name)}" if name else "an operator"
    return f"<h1>Log in</h1><p>You are logged in as {who} (log out at the top).</p>"


def robot_path(robot_id: str) -> str:
    return "/robots/" + quote(robot_id, safe="")


def confirm_restart(robot_id: str, who: Identity, outcome: Outcome | None) -> str:
    """The confirmation page's body: what a restart does, and the form that asks for it."""
    path = robot_path(robot_id)
    rid = esc(robot_id)
    csrf = f'<input type="hidden" name="csrf" value="{esc(who.csrf)}">' if who.csrf else ""
    return (
        f"<h1>Restart {rid}?</h1><div>"
        f"<p>{rid}'s agent stops its brain (SIGTERM, then SIGKILL after its stop timeout) "
        "and starts it again with the launch request it has; its restart count and backoff "
        "start over. A busy brain (its hold file) defers it. No commit is needed.</p>"
        f"{outcome_html(outcome)}"
        f'<form method="post" action="{path}/restart" data-confirm-restart>{csrf}'
        f'<button type="submit">Restart {rid}</button> <a href="{path}">Cancel</a></form></div>'
    )


def outcome_html(outcome: Outcome | None) -> str:
    """The latest restart the UI asked of a robot (`[data-restart-outcome]`, its state as the
    attribute's value), or nothing."""
    if outcome is None:
        return ""
    at = time.strftime("%H:%M:%S UTC", time.gmtime(outcome.at))
    who = f"by {esc(outcome.by)} at {at}"
    rid = esc(outcome.robot_id)
    if outcome.state == "pending":
        text = f"Restart asked {who}: waiting for {rid} to confirm (reload to see)."
    elif outcome.state == "confirmed":
        text = f"Restart asked {who}: {rid} confirmed it: {esc(outcome.text)}."
    else:
        text = f"Restart asked {who}: not done: {esc(outcome.text)}"
    return (
        f'<p class="outcome outcome-{outcome.state}" role="status" '
        f'data-restart-outcome="{outcome.state}" '
        f'data-outcome-src="{robot_path(outcome.robot_id)}/restart/outcome">{text}</p>'
    )


def refusal(title: str, message: str, link: tuple[str, str] | None = None) -> str:
    """A refused request's page body (401, 403, 404, 429...)."""
    more = ""
    if link is not None:
        more = f' <a href="{esc(link[0])}">{esc(link[1])}</a>'
    return f'<h1>{esc(title)}</h1><p role="alert">{esc(message)}{more}</p>'


_DOES = {
    "resume": (
        "Resume the rollout",
        "The wave paused for inconclusive evidence (too few goals by rollout.verify's timeout) "
        "passes as it is, and the next wave starts. The reconciler keeps the decision, with "
        "your name, as a git note on the revision.",
    ),
    "abort": (
        "Abort the rollout",
        "The rollout stops as a failed wave: its robots get the last revision that fully "
        "rolled out (rollout.on_failure: halt keeps them where they are). The reconciler keeps "
        "the decision, with your name, as a git note on the revision.",
    ),
}


def confirm_decision(action: str, who: Identity, latest: Decision | None) -> str:
    """The confirmation page's body for a rollout decision, and the form that asks for it."""
    title, does = _DOES[action]
    csrf = f'<input type="hidden" name="csrf" value="{esc(who.csrf)}">' if who.csrf else ""
    return (
        f"<h1>{esc(title)}?</h1><div><p>{esc(does)}</p>{decision_html(latest)}"
        f'<form method="post" action="/rollout/{action}" data-confirm-rollout>{csrf}'
        f'<button type="submit">{esc(title)}</button> <a href="/">Cancel</a></form></div>'
    )


def decision_html(decision: Decision | None) -> str:
    """The latest rollout decision the UI sent (`[data-rollout-decision]`), or nothing."""
    if decision is None:
        return ""
    at = time.strftime("%H:%M:%S UTC", time.gmtime(decision.at))
    asked = f"{decision.action.capitalize()} asked by {esc(decision.by)} at {at}"
    if decision.state == "pending":
        text = f"{asked}: waiting for the reconciler (reload to see)."
    elif decision.state == "confirmed":
        text = f"{asked}: {esc(decision.text)}."
    else:
        text = f"{asked}: not done: {esc(decision.text)}"
    return (
        f'<p class="outcome outcome-{decision.state}" role="status" '
        f'data-rollout-decision="{decision.state}">{text}</p>'
    )
