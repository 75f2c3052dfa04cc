"""The write side's routes without sockets or a broker: who may do what, what a refused
request gets, where a login sends, and that no page shows a secret."""

from __future__ import annotations

import http.client
import re
from urllib.parse import urlencode

import pytest

from robotconf.readmodel.http_edge import Request, Response
from robotconf.workstation.ui import forms
from robotconf.workstation.ui.actions import Actions
from robotconf.workstation.ui.auth import COOKIE, Identity, OperatorAuth, Policy
from robotconf.workstation.ui.restarts import Outcome
from robotconf.workstation.ui.server import Route

TOKEN = "operator-token-" + "q9" * 10
FORM = "application/x-www-form-urlencoded"


def message(**values: str) -> http.client.HTTPMessage:
    headers = http.client.HTTPMessage()
    for name, value in values.items():
        headers[name.replace("_", "-")] = value
    return headers


class UI:
    """The action routes on an auth with no broker behind (restarts and logs: 503)."""

    def __init__(
        self, token: str | None = TOKEN, policy: Policy | None = None, link_login: bool = False
    ) -> None:
        self.auth = OperatorAuth(token, policy=policy)
        self.routes: list[Route] = Actions(self.auth, None, None, link_login=link_login).routes()

    def ask(
        self,
        method: str,
        target: str,
        body: bytes | str = b"",
        client: str = "192.0.2.1",
        **headers: str,
    ) -> Response:
        data = body.encode() if isinstance(body, str) else body
        request = Request(client, method, target, message(**headers), data)
        who = self.auth.identify(request.headers)
        path = target.partition("?")[0]
        for route in self.routes:
            found = route.pattern.fullmatch(path)
            if route.method == method and found is not None:
                return route.handler(request, found, who)
        raise AssertionError(f"no route for {method} {path}")

    def login(self, client: str = "192.0.2.1") -> tuple[str, Identity]:
        answer = self.ask("POST", "/login", urlencode({"token": TOKEN}), client, Content_Type=FORM)
        assert answer.code == 303
        cookie = dict(answer.headers)["Set-Cookie"].split(";")[0]
        return cookie, self.auth.identify(message(Cookie=cookie))


def header(answer: Response, name: str) -> str | None:
    return dict(answer.headers).get(name)


def test_the_login_page_has_the_contracts_form_and_a_read_only_ui_says_so() -> None:
    page = UI().ask("GET", "/login?next=/robots/tb3-01").body.decode()
    assert "<form" in page and "data-login" in page and 'name="token"' in page
    assert 'value="/robots/tb3-01"' in page
    assert "Content-Security-Policy" in dict(UI().ask("GET", "/login").headers)
    closed = UI(None).ask("GET", "/login").body.decode()
    assert "read-only" in closed and "data-login>" not in closed


def test_a_login_sets_the_cookie_and_sends_to_a_local_next_only() -> None:
    ui = UI()
    for given, sent in [
        ("/robots/tb3-01", "/robots/tb3-01"),
        ("/?verdict=Failed", "/?verdict=Failed"),
        ("//evil.example/x", "/"),
        ("/\\evil.example", "/"),
        ("https://evil.example/", "/"),
        ("javascript:alert(1)", "/"),
        ("/\r\nSet-Cookie: x=y", "/"),
        ("", "/"),
    ]:
        body = urlencode({"token": TOKEN, "next": given})
        answer = ui.ask("POST", "/login", body, Content_Type=FORM)
        assert answer.code == 303 and header(answer, "Location") == sent, given
        cookie = header(answer, "Set-Cookie")
        assert cookie is not None and cookie.startswith(f"{COOKIE}=") and TOKEN not in cookie


def test_a_wrong_token_is_refused_then_throttled_without_a_hint() -> None:
    ui = UI(policy=Policy(guesses=3))
    for n in range(3):
        guess = urlencode({"token": f"guess-{n}-" + "z" * 20})
        answer = ui.ask("POST", "/login", guess, Content_Type=FORM)
        assert answer.code == 401 and header(answer, "Set-Cookie") is None
        assert "not the operator token" in answer.body.decode()
    right = ui.ask("POST", "/login", urlencode({"token": TOKEN}), Content_Type=FORM)
    assert right.code == 429 and header(right, "Retry-After") is not None
    assert header(right, "Set-Cookie") is None
    # Another address still logs in; a Bearer from the throttled one is held too.
    assert (
        ui.ask("POST", "/login", urlencode({"token": TOKEN}), "192.0.2.99", Content_Type=FORM).code
        == 303
    )
    held = ui.ask("GET", "/robots/tb3-01/restart", Authorization=f"Bearer {TOKEN}")
    assert held.code == 429


def test_up_s_login_link_logs_in_and_sends_to_a_local_next_only() -> None:
    ui = UI(link_login=True)
    answer = ui.ask("GET", "/login?" + urlencode({"token": TOKEN}), Sec_Fetch_Site="none")
    assert answer.code == 303 and header(answer, "Location") == "/"
    cookie = header(answer, "Set-Cookie")
    assert cookie is not None and cookie.startswith(f"{COOKIE}=") and "HttpOnly" in cookie
    assert ui.auth.identify(message(Cookie=cookie.split(";")[0])).operator
    onward = ui.ask("GET", "/login?" + urlencode({"token": TOKEN, "next": "/robots/tb3-01"}))
    assert header(onward, "Location") == "/robots/tb3-01"
    away = ui.ask("GET", "/login?" + urlencode({"token": TOKEN, "next": "//evil.example/"}))
    assert header(away, "Location") == "/"


def test_up_s_login_link_refuses_a_wrong_token_another_site_and_other_uis() -> None:
    ui = UI(link_login=True, policy=Policy(guesses=2))
    for _ in range(2):
        wrong = ui.ask("GET", "/login?token=not-the-token-00000000")
        assert wrong.code == 401 and header(wrong, "Set-Cookie") is None
        assert TOKEN not in wrong.body.decode()
    throttled = ui.ask("GET", "/login?" + urlencode({"token": TOKEN}))
    assert throttled.code == 429 and header(throttled, "Set-Cookie") is None
    foreign = UI(link_login=True).ask(
        "GET", "/login?" + urlencode({"token": TOKEN}), Sec_Fetch_Site="cross-site"
    )
    assert foreign.code == 403 and header(foreign, "Set-Cookie") is None
    # `robotconf ui`'s: a token in an address is no login there (the form is shown).
    form = UI().ask("GET", "/login?" + urlencode({"token": TOKEN}))
    assert form.code == 200 and header(form, "Set-Cookie") is None
    assert "data-login" in form.body.decode()


@pytest.mark.parametrize(
    ("body", "headers", "code"),
    [
        ("token=x", {"Content_Type": "text/plain"}, 415),
        ("token=x", {}, 415),
        ('{"token": "x"}', {"Content_Type": "application/json"}, 415),
        ("token=" + "x" * 5000, {"Content_Type": FORM}, 413),
        (b"token=\xff\xfe", {"Content_Type": FORM}, 400),
        ("token=a&token=b", {"Content_Type": FORM}, 400),
        ("&".join(f"f{n}=1" for n in range(50)), {"Content_Type": FORM}, 400),
        ("next=/", {"Content_Type": FORM}, 400),
    ],
)
def test_a_malformed_login_is_refused_with_a_page(
    body: str | bytes, headers: dict[str, str], code: int
) -> None:
    answer = UI().ask("POST", "/login", body, **headers)
    assert answer.code == code
    assert answer.content_type.startswith("text/html") and b"Traceback" not in answer.body


def test_a_login_form_from_another_site_is_refused() -> None:
    ui = UI()
    body = urlencode({"token": TOKEN})
    for headers in [
        {"Origin": "https://evil.example", "Host": "127.0.0.1:8765"},
        {"Origin": "null", "Host": "127.0.0.1:8765"},
        {"Sec_Fetch_Site": "cross-site"},
        {"Sec_Fetch_Site": "same-site"},
    ]:
        assert ui.ask("POST", "/login", body, Content_Type=FORM, **headers).code == 403
    same = {"Origin": "http://127.0.0.1:8765", "Host": "127.0.0.1:8765"}
    assert ui.ask("POST", "/login", body, Content_Type=FORM, **same).code == 303
    # Chromium's own form under a strict Referrer-Policy: Origin null, Sec-Fetch-Site says.
    own = {"Origin": "null", "Sec_Fetch_Site": "same-origin", "Host": "127.0.0.1:8765"}
    assert ui.ask("POST", "/login", body, Content_Type=FORM, **own).code == 303


def test_a_viewer_gets_401_a_wrong_token_403_and_an_operator_the_confirmation() -> None:
    ui = UI()
    viewer = ui.ask("GET", "/robots/tb3-01/restart")
    assert viewer.code == 401 and "Bearer" in (header(viewer, "WWW-Authenticate") or "")
    assert ui.ask("POST", "/robots/tb3-01/restart").code == 401
    assert ui.ask("GET", "/robots/tb3-01/logs").code == 401
    wrong = {"Authorization": "Bearer not-the-token-at-all-xx"}
    assert ui.ask("GET", "/robots/tb3-01/restart", **wrong).code == 403
    assert ui.ask("POST", "/robots/tb3-01/restart", **wrong).code == 403
    assert ui.ask("GET", "/robots/tb3-01/logs", **wrong).code == 403
    cookie, who = ui.login()
    page = ui.ask("GET", "/robots/tb3-01/restart", Cookie=cookie)
    text = page.body.decode()
    assert page.code == 200 and "data-confirm-restart" in text
    assert f'name="csrf" value="{who.csrf}"' in text and "Restart tb3-01" in text
    assert re.search(r'<form method="post" action="/robots/tb3-01/restart"', text)


def test_a_restart_with_a_stale_csrf_is_403_and_a_forged_cookie_401() -> None:
    ui = UI()
    cookie, who = ui.login()
    for csrf in ["", "x" * 43, who.csrf + "x"]:
        answer = ui.ask(
            "POST",
            "/robots/tb3-01/restart",
            urlencode({"csrf": csrf}),
            Cookie=cookie,
            Content_Type=FORM,
        )
        assert answer.code == 403, csrf
    no_form = ui.ask("POST", "/robots/tb3-01/restart", Cookie=cookie)
    assert no_form.code == 415
    forged = f"{COOKIE}=" + "A" * 43
    answer = ui.ask(
        "POST",
        "/robots/tb3-01/restart",
        urlencode({"csrf": who.csrf}),
        Cookie=forged,
        Content_Type=FORM,
    )
    assert answer.code == 401
    # The right csrf passes the checks: here no broker is behind, so 503.
    good = ui.ask(
        "POST",
        "/robots/tb3-01/restart",
        urlencode({"csrf": who.csrf}),
        Cookie=cookie,
        Content_Type=FORM,
    )
    assert good.code == 503
    bearer = ui.ask("POST", "/robots/tb3-01/restart", Authorization=f"Bearer {TOKEN}")
    assert bearer.code == 503


def test_a_bad_robot_id_is_404_for_an_operator() -> None:
    ui = UI()
    bearer = {"Authorization": f"Bearer {TOKEN}"}
    for target in [
        "/robots/%3Cscript%3E/restart",
        "/robots/..%2F..%2Fetc/restart",
        "/robots/UPPER_and spaces/restart",
    ]:
        answer = ui.ask("GET", target, **bearer)
        assert answer.code == 404, target
        assert b"<script>" not in answer.body


def test_logout_needs_the_sessions_csrf_and_ends_it() -> None:
    ui = UI()
    cookie, who = ui.login()
    stale = ui.ask("POST", "/logout", urlencode({"csrf": "nope"}), Cookie=cookie, Content_Type=FORM)
    assert stale.code == 403 and ui.auth.identify(message(Cookie=cookie)).operator
    out = ui.ask("POST", "/logout", urlencode({"csrf": who.csrf}), Cookie=cookie, Content_Type=FORM)
    assert out.code == 303 and "Max-Age=0" in (header(out, "Set-Cookie") or "")
    assert not ui.auth.identify(message(Cookie=cookie)).operator


def test_no_page_shows_a_secret() -> None:
    """The token, a session id: in no page, header or outcome; the CSRF token only in the
    session's own forms."""
    ui = UI()
    cookie, who = ui.login()
    session_id = cookie.split("=", 1)[1]
    answers = [
        ui.ask("GET", "/login", Cookie=cookie),
        ui.ask("GET", "/login"),
        ui.ask("GET", "/robots/tb3-01/restart", Cookie=cookie),
        ui.ask("GET", "/robots/tb3-01/restart", Authorization=f"Bearer {TOKEN}"),
        ui.ask("POST", "/login", urlencode({"token": TOKEN[:-1] + "!"}), Content_Type=FORM),
        ui.ask("POST", "/login", urlencode({"token": TOKEN}), Content_Type=FORM),
        ui.ask("POST", "/robots/tb3-01/restart", Authorization=f"Bearer {TOKEN}x"),
    ]
    for answer in answers:
        shown = answer.body.decode() + repr(answer.headers)
        assert TOKEN not in shown and TOKEN[:-1] not in shown
        assert session_id not in answer.body.decode()
    bearer_page = answers[3].body.decode()
    assert who.csrf not in bearer_page
    assert re.findall(r'name="csrf" value="([^"]*)"', bearer_page) in ([], [""])


def test_robot_text_in_an_outcome_is_escaped() -> None:
    outcome = Outcome("tb3-01", "failed", "ui.cookie", 0.0, "<script>alert(1)</script>")
    html = forms.outcome_html(outcome)
    assert "<script>" not in html and "&lt;script&gt;" in html
    assert 'data-restart-outcome="failed"' in html
    assert forms.outcome_html(None) == ""


def test_named_operators_log_in_with_their_name_and_the_log_says_who(
    caplog: pytest.LogCaptureFixture,
) -> None:
    from robotconf.workstation.ui.operators import MIN_COST, hash_token, parse_operators

    hashed = hash_token(TOKEN, MIN_COST).text()
    ui = UI(None)
    ui.auth = OperatorAuth(None, operators=parse_operators(f"alice {hashed}\n", "ops"))
    ui.routes = Actions(ui.auth, None, None).routes()
    form = ui.ask("GET", "/login").body.decode()
    assert 'id="username" name="username"' in form and "hidden>" not in form
    caplog.set_level("INFO", logger="robotconf.ui")
    wrong = urlencode({"username": "bob", "token": TOKEN})
    refused = ui.ask("POST", "/login", wrong, Content_Type=FORM)
    assert refused.code == 401 and "name and token are not" in refused.body.decode()
    evil = urlencode({"username": "x\r\nforged", "token": TOKEN})
    assert ui.ask("POST", "/login", evil, Content_Type=FORM).code == 401
    right = urlencode({"username": "alice", "token": TOKEN})
    answer = ui.ask("POST", "/login", right, Content_Type=FORM)
    assert answer.code == 303
    cookie = dict(answer.headers)["Set-Cookie"].split(";")[0]
    page = ui.ask("GET", "/login", Cookie=cookie).body.decode()
    assert "logged in as the operator alice" in page and "operator alice</span>" in page
    said = caplog.text
    assert "ui: alice logged in from 192.0.2.1" in said
    assert "ui: login as bob from 192.0.2.1 refused: wrong" in said
    assert "\r" not in said and "\nforged" not in said and TOKEN not in said
    wrong_bearer = ui.ask("GET", "/robots/tb3-01/restart", Authorization=f"Bearer {TOKEN}")
    assert (
        wrong_bearer.code == 403 and "operator&#x27;s name and token" in wrong_bearer.body.decode()
    )
