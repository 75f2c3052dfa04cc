"""The UI's write side, its routes: log in and out, a robot's restart (confirmed, then sent as
`robotconf restart` sends it) and its brain's log stream, for operators only."""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from urllib.parse import parse_qsl, urlencode

from robotconf.configurator.types import is_robot_id
from robotconf.contract.textsafe import printable
from robotconf.readmodel.http_edge import FedStream, Request, Response
from robotconf.workstation.ui import forms
from robotconf.workstation.ui.auth import MAX_TOKEN, Identity, OperatorAuth, refusal_text
from robotconf.workstation.ui.logtail import LogTails
from robotconf.workstation.ui.operators import MAX_NAME, name_problem
from robotconf.workstation.ui.pages import page
from robotconf.workstation.ui.restarts import Restarts
from robotconf.workstation.ui.rollout_decisions import Decisions
from robotconf.workstation.ui.server import CSP, Handler, Route

MAX_FORM = 4096  # bytes of a form body: a token, a CSRF token and a path fit
MAX_FIELDS = 8
log = logging.getLogger("robotconf.ui")
FORM_TYPE = "application/x-www-form-urlencoded"
LOG_BACKLOG = 64  # log events waiting for a slow page; beyond, its stream ends (it reconnects)
PAGE_HEADERS = (
    ("Content-Security-Policy", CSP),
    ("X-Content-Type-Options", "nosniff"),
    ("Cache-Control", "no-store"),
)

# title, body (HTML), who: the whole page, in the UI's frame.
Layout = Callable[[str, str, Identity], bytes]


def framed(title: str, body: str, who: Identity) -> bytes:
    return page(title, body, who).encode("utf-8")


class Refused(Exception):
    """A request refused before its action: the code, and the page's words."""

    def __init__(
        self,
        code: int,
        message: str,
        *headers: tuple[str, str],
        link: tuple[str, str] | None = None,
    ) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.headers = headers
        self.link = link  # where to go from here: (path, words)


class Actions:
    """The write side's routes, on one auth, one restarter and one log follower (None: a UI
    with no broker to act through, whose operators can only look)."""

    def __init__(
        self,
        auth: OperatorAuth,
        restarts: Restarts | None,
        tails: LogTails | None,
        layout: Layout = framed,
        decisions: Decisions | None = None,
        link_login: bool = False,
    ) -> None:
        self.auth = auth
        # `up --ui`'s printed link, /login?token=...: on loopback only, where the token in an
        # address reaches no proxy's log (Jupyter's way); elsewhere the form alone.
        self.link_login = link_login
        self.restarts = restarts
        self.tails = tails
        self.layout = layout
        self.decisions = decisions

    def routes(self) -> list[Route]:
        robot = r"/robots/(?P<id>[^/]{1,200})"
        table: list[tuple[str, str, Handler]] = [
            ("GET", "/login", self.login_page),
            ("POST", "/login", self.login),
            ("POST", "/logout", self.logout),
            ("GET", robot + "/restart", self.confirm_restart),
            ("POST", robot + "/restart", self.restart),
            ("GET", robot + "/restart/outcome", self.outcome),
            ("GET", robot + "/logs", self.logs),
            ("GET", r"/rollout/(?P<action>resume|abort)", self.confirm_decision),
            ("POST", r"/rollout/(?P<action>resume|abort)", self.decide),
        ]
        return [Route(m, re.compile(p), self._guard(h)) for m, p, h in table]

    def _guard(self, handler: Handler) -> Handler:
        def guarded(request: Request, match: re.Match[str], who: Identity) -> Response:
            try:
                return handler(request, match, who)
            except Refused as refused:
                body = forms.refusal(f"{refused.code}", refused.message, refused.link)
                return self.page(refused.code, "Refused", body, who, *refused.headers)

        return guarded

    def page(
        self, code: int, title: str, body: str, who: Identity, *headers: tuple[str, str]
    ) -> Response:
        return Response(
            code,
            self.layout(title, body, who),
            "text/html; charset=utf-8",
            headers=PAGE_HEADERS + headers,
        )

    # ------------------------------------------------------------------ login, logout

    def login_page(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        next_path = _query_field(request.target, "next")
        token = _query_field(request.target, "token")
        if token and self.link_login:
            return self.login_link(request, token, next_path, who)
        if who.operator and who.via == "cookie":
            return self.page(200, "Log in", forms.logged_in(who.name), who)
        body = forms.login_form(next_path, enabled=self.auth.enabled, named=self.auth.named)
        return self.page(200, "Log in", body, who)

    def login(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        _same_origin(request)
        fields = _form(request)
        next_path = forms.local_path(fields.get("next"))
        if not self.auth.enabled:
            body = forms.login_form(next_path, enabled=False)
            return self.page(403, "Log in", body, who)
        token = fields.get("token")
        if token is None:
            raise Refused(400, "the login form has no token field")
        name = fields.get("username", "")[: MAX_NAME + 1] if self.auth.named else ""
        return self._logged_in(request, token, next_path, who, name)

    def _logged_in(
        self, request: Request, token: str, next_path: str, who: Identity, name: str = ""
    ) -> Response:
        """A login with `token` (and a named operator's `name`): on to `next_path` with the
        session cookie, or the form again saying why not. Each is a line of the UI's log."""
        client = self.auth.client(request.client, request.headers)
        result = self.auth.login(client, token[: MAX_TOKEN + 1], name)
        named = self.auth.named
        said = _operator_name(name) if named else "the operator"
        if result.cookie is not None:
            log.info("ui: %s logged in from %s", said, client)
            self.auth.logout(request.headers)  # a session it had ends: one per login
            return _see_other(next_path, ("Set-Cookie", result.cookie))
        log.info("ui: login as %s from %s refused: %s", said, client, result.refusal)
        body = forms.login_form(
            next_path, refusal_text(result, named), enabled=self.auth.enabled, named=named
        )
        if result.refusal == "throttled":
            return self.page(429, "Log in", body, who, ("Retry-After", str(result.retry_after)))
        return self.page(403 if result.refusal == "disabled" else 401, "Log in", body, who)

    def login_link(self, request: Request, token: str, next_path: str, who: Identity) -> Response:
        """`up --ui`'s login link: the token as the form would send it (compared in constant
        time, throttled alike), then on to `next` with the session cookie. Opened from a
        terminal or typed, never followed from another site's page."""
        if (request.headers.get("Sec-Fetch-Site") or "none").strip() not in ("none", "same-origin"):
            raise Refused(
                403,
                "a login link followed from another site is refused: open it "
                "from the terminal that printed it, or paste it into the address bar",
            )
        return self._logged_in(request, token, forms.local_path(next_path), who)

    def logout(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        _same_origin(request)
        fields = _form(request)
        if who.via == "cookie" and not who.csrf_matches(fields.get("csrf", "")):
            raise Refused(403, "the form is stale (its CSRF token does not match): reload it")
        return _see_other("/", ("Set-Cookie", self.auth.logout(request.headers)))

    # ------------------------------------------------------------------ restart

    def confirm_restart(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        robot_id = self._operator(request, match, who)
        outcome = self.restarts.outcome(robot_id) if self.restarts else None
        body = forms.confirm_restart(robot_id, who, outcome)
        return self.page(200, f"Restart {robot_id}?", body, who)

    def restart(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        robot_id = self._operator(request, match, who)
        _posted(request, who)
        if self.restarts is None:
            raise Refused(503, "this UI has no broker to send a restart through")
        client = self.auth.client(request.client, request.headers)
        started = self.restarts.start(robot_id, who.by, client)
        if started == "busy":
            raise Refused(503, "too many restarts are waiting for their robots: try again soon")
        return _see_other(forms.robot_path(robot_id))

    def outcome(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        """The restart outcome fragment, for the script to refresh a pending one."""
        robot_id = self._operator(request, match, who)
        outcome = self.restarts.outcome(robot_id) if self.restarts else None
        body = forms.outcome_html(outcome).encode()
        return Response(200, body, "text/html; charset=utf-8", headers=PAGE_HEADERS)

    def outcome_html(self, robot_id: str) -> str:
        """The robot page's outcome of the latest restart asked of `robot_id`, if any."""
        return forms.outcome_html(self.restarts.outcome(robot_id) if self.restarts else None)

    # ------------------------------------------------------------------ rollout decisions

    def confirm_decision(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        self._require_operator(request, who)
        action = match.group("action")
        latest = self.decisions.latest if self.decisions else None
        body = forms.confirm_decision(action, who, latest)
        return self.page(200, f"{action.capitalize()} the rollout?", body, who)

    def decide(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        """An operator's resume or abort, sent as `robotconf rollout` sends it; the page
        that follows shows the reconciler's answer once it comes."""
        self._require_operator(request, who)
        _posted(request, who)
        if self.decisions is None:
            raise Refused(503, "this UI has no broker to send a decision through")
        action = match.group("action")
        client = self.auth.client(request.client, request.headers)
        if self.decisions.start("resume" if action == "resume" else "abort", who.by, client) == (
            "already"
        ):
            raise Refused(409, "a decision is waiting for the reconciler's answer: reload soon")
        return _see_other(f"/rollout/{action}")

    # ------------------------------------------------------------------ logs

    def logs(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        robot_id = self._operator(request, match, who)
        if request.method == "HEAD":
            return Response(200, b"", "text/event-stream; charset=utf-8", headers=PAGE_HEADERS)
        tails = self.tails
        if tails is None:
            raise Refused(503, "this UI has no broker to read a robot's log through")
        if not tails.reserve():
            raise Refused(503, f"{tails.limit} log streams are open, the most this UI serves")
        feed = FedStream(LOG_BACKLOG)
        tails.follow(robot_id, feed)
        return Response(
            200,
            b"retry: 10000\n\n",  # a robot offline is not asked again and again
            "text/event-stream; charset=utf-8",
            headers=PAGE_HEADERS,
            stream=feed,
            keepalive=b": keep-alive\n\n",
        )

    # ------------------------------------------------------------------ who may

    def _operator(self, request: Request, match: re.Match[str], who: Identity) -> str:
        """The robot id of an operator's request; Refused otherwise (`_require_operator`)."""
        self._require_operator(request, who)
        robot_id = match.group("id")
        if not is_robot_id(robot_id):
            raise Refused(404, "no such robot: not a robot id")
        return robot_id

    def _require_operator(self, request: Request, who: Identity) -> None:
        """Refused unless an operator asks: 401 without credentials, 403 with a wrong token,
        429 for an address that guessed too often."""
        client = self.auth.client(request.client, request.headers)
        if who.via == "bearer" and not who.operator:
            self.auth.failed(client)
        wait = self.auth.blocked(client) if who.via == "bearer" else 0
        if wait:
            raise Refused(
                429, "too many wrong tokens from this address", ("Retry-After", str(wait))
            )
        if who.via == "anonymous":
            back = forms.local_path(request.target)
            raise Refused(
                401,
                "operators only (viewers may look, not act):",
                ("WWW-Authenticate", 'Bearer realm="robotconf"'),
                link=("/login?" + urlencode({"next": back}), "log in"),
            )
        if not who.operator:
            said = "an operator's name and token" if self.auth.named else "the operator token"
            raise Refused(403, f"that is not {said}")


def _operator_name(name: str) -> str:
    """A name given at login as the log may show it: one that could be an operator's, else
    what it is not (an attacker's text never reaches the log as it is)."""
    return name if name_problem(name) is None else f"a bad name ({printable(name[:40])!r})"


def _posted(request: Request, who: Identity) -> None:
    """An operator's form, from this origin and, with a login cookie, with the session's CSRF
    token; Refused otherwise."""
    _same_origin(request)
    if who.via == "cookie":
        fields = _form(request)
        if not who.csrf_matches(fields.get("csrf", "")):
            raise Refused(403, "the form is stale (its CSRF token does not match): reload it")
    elif request.body:
        _form(request)  # a script's body is a form too, or nothing


def _see_other(path: str, *headers: tuple[str, str]) -> Response:
    return Response(303, b"", headers=(("Location", path), *PAGE_HEADERS, *headers))


def _query_field(target: str, name: str) -> str:
    query = target.partition("?")[2]
    try:
        fields = parse_qsl(query, max_num_fields=MAX_FIELDS)
    except ValueError:
        return ""
    return next((value for key, value in fields if key == name), "")


def _form(request: Request) -> dict[str, str]:
    """The fields of a POSTed form; Refused when the body is not a small url-encoded form."""
    kind = (request.headers.get("Content-Type") or "").split(";")[0].strip().lower()
    if kind != FORM_TYPE:
        raise Refused(415, f"a form is sent as {FORM_TYPE}")
    if len(request.body) > MAX_FORM:
        raise Refused(413, f"a form is at most {MAX_FORM} bytes")
    try:
        text = request.body.decode("ascii")
        pairs = parse_qsl(text, keep_blank_values=True, max_num_fields=MAX_FIELDS)
    except (UnicodeDecodeError, ValueError):
        raise Refused(400, "the form is not a small url-encoded form") from None
    fields = dict(pairs)
    if len(fields) != len(pairs):
        raise Refused(400, "a form field is given twice")
    return fields


def _same_origin(request: Request) -> None:
    """Refused when the browser says the form came from another site: SameSite cookies
    already stop that; this stops it again, and for the login form, which has no session
    yet. Sec-Fetch-Site where the browser sends it; else the Origin, when there is one
    (a browser may send `Origin: null` for its own page's form: only Sec-Fetch-Site is
    trusted to say same-origin then)."""
    headers = request.headers
    site = headers.get("Sec-Fetch-Site")
    if site is not None:
        if site.strip() not in ("same-origin", "none"):
            raise Refused(403, "a form from another site is refused")
        return
    origin = headers.get("Origin")
    if origin is None:
        return  # not a browser's cross-site form (those carry an Origin): a script
    host = (headers.get("Host") or "").strip()
    if not host or origin.strip() not in (f"http://{host}", f"https://{host}"):
        raise Refused(403, "a form from another site is refused")
