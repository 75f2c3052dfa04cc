"""The UI's operator auth without sockets: the token file's rules, Bearer and cookie sessions,
expiry, CSRF, throttled guesses, and the cookie's flags."""

from __future__ import annotations

import email.message
import os
from pathlib import Path

import pytest

from robotconf.contract.errors import CliError
from robotconf.workstation.ui.auth import (
    ANONYMOUS,
    COOKIE,
    Identity,
    OperatorAuth,
    Policy,
    own_token,
    read_token,
    session_cookie,
)

TOKEN = "tok-" + "x7" * 12


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def headers(**values: str | list[str]) -> email.message.Message:
    message = email.message.Message()
    for name, value in values.items():
        for one in value if isinstance(value, list) else [value]:
            message[name.replace("_", "-")] = one
    return message


def token_file(tmp_path: Path, text: str, mode: int = 0o600) -> Path:
    path = tmp_path / "token"
    path.write_text(text, encoding="utf-8")
    path.chmod(mode)
    return path


def logged_in(auth: OperatorAuth, client: str = "10.0.0.1") -> tuple[str, Identity]:
    """The session id of a fresh login, and who its cookie identifies."""
    login = auth.login(client, TOKEN)
    assert login.cookie is not None and login.refusal == ""
    session_id = login.cookie.split(";")[0].split("=", 1)[1]
    who = auth.identify(headers(Cookie=f"{COOKIE}={session_id}"))
    return session_id, who


# ---------------------------------------------------------------- the token file


def test_the_token_file_gives_its_one_line(tmp_path: Path) -> None:
    assert read_token(token_file(tmp_path, TOKEN + "\n")) == TOKEN
    assert read_token(token_file(tmp_path, TOKEN + "\r\n")) == TOKEN
    assert read_token(token_file(tmp_path, TOKEN)) == TOKEN
    assert OperatorAuth.from_file(token_file(tmp_path, TOKEN)).enabled
    assert not OperatorAuth.from_file(None).enabled


def test_an_own_token_is_made_once_readable_by_its_owner_alone(tmp_path: Path) -> None:
    path = tmp_path / "up" / "ui.token"
    token, made = own_token(path, "up's operator token file")
    assert made and len(token) >= 43 and path.read_text() == token + "\n"
    assert path.stat().st_mode & 0o777 == 0o600
    assert own_token(path, "up's operator token file") == (token, False)  # kept, not remade
    assert read_token(path) == token


def test_an_own_token_others_may_read_is_refused_not_replaced(tmp_path: Path) -> None:
    path = token_file(tmp_path, TOKEN, 0o644)
    with pytest.raises(CliError, match=r"^up's operator token file .* \(mode 0644\): chmod 600"):
        own_token(path, "up's operator token file")
    assert path.read_text() == TOKEN


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o620, 0o666])
def test_a_token_file_others_may_read_or_change_is_refused(tmp_path: Path, mode: int) -> None:
    with pytest.raises(CliError, match=f"mode {mode:04o}.*chmod 600"):
        read_token(token_file(tmp_path, TOKEN, mode))


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("", "one line"),
        ("short-token\n", "shorter than 16"),
        (TOKEN + "\nsecond line\n", "one line"),
        ("with a space in it, long enough\n", "one line"),
        ("tøken-with-non-ascii-letters\n", "one line"),
        ("x" * 5000, "longer than 1024"),
    ],
)
def test_a_token_file_without_one_good_token_is_refused(
    tmp_path: Path, text: str, why: str
) -> None:
    with pytest.raises(CliError, match=why) as refused:
        read_token(token_file(tmp_path, text))
    assert "second line" not in str(refused.value) and "x" * 20 not in str(refused.value)


def test_a_missing_token_file_or_a_folder_or_a_fifo_is_refused(tmp_path: Path) -> None:
    with pytest.raises(CliError, match="cannot read"):
        read_token(tmp_path / "missing")
    folder = tmp_path / "folder"
    folder.mkdir(mode=0o700)
    with pytest.raises(CliError, match=r"not a regular file|cannot read"):
        read_token(folder)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    with pytest.raises(CliError, match="not a regular file"):  # and does not hang
        read_token(fifo)


# ---------------------------------------------------------------- bearer


def test_a_bearer_token_makes_an_operator_and_a_wrong_one_does_not() -> None:
    auth = OperatorAuth(TOKEN)
    assert auth.identify(headers(Authorization=f"Bearer {TOKEN}")) == Identity(
        operator=True, via="bearer"
    )
    for value in [
        "Bearer wrong-token-of-some-length",
        f"Bearer {TOKEN}x",
        f"Bearer {TOKEN[:-1]}",
        f"Basic {TOKEN}",
        "Bearer",
        "Bearer \u00e9\u00e9\u00e9",
        "",
    ]:
        who = auth.identify(headers(Authorization=value))
        assert who == Identity(operator=False, via="bearer"), value
    two = headers(Authorization=[f"Bearer {TOKEN}", "Bearer other"])
    assert not auth.identify(two).operator
    assert OperatorAuth(None).identify(headers(Authorization=f"Bearer {TOKEN}")).operator is False


def test_no_credentials_is_anonymous() -> None:
    auth = OperatorAuth(TOKEN)
    assert auth.identify(headers()) == ANONYMOUS
    assert ANONYMOUS.via == "anonymous" and not ANONYMOUS.operator


# ---------------------------------------------------------------- sessions


def test_a_login_sets_a_session_cookie_that_is_not_the_token() -> None:
    auth = OperatorAuth(TOKEN)
    login = auth.login("10.0.0.1", TOKEN)
    assert login.cookie is not None
    assert TOKEN not in login.cookie
    flags = [part.strip() for part in login.cookie.split(";")]
    assert flags[0].startswith(f"{COOKIE}=")
    assert {"Path=/", "HttpOnly", "SameSite=Strict"} <= set(flags)
    assert "Secure" not in flags
    session_id, who = logged_in(auth)
    assert who.operator and who.via == "cookie" and len(who.csrf) >= 32
    assert who.csrf != session_id and TOKEN not in repr(who) and who.csrf not in repr(who)


def test_over_tls_the_cookie_is_secure() -> None:
    login = OperatorAuth(TOKEN, secure=True).login("10.0.0.1", TOKEN)
    assert login.cookie is not None and "Secure" in [p.strip() for p in login.cookie.split(";")]


def test_each_session_has_its_own_csrf_token() -> None:
    auth = OperatorAuth(TOKEN)
    _, one = logged_in(auth)
    _, two = logged_in(auth)
    assert one.csrf != two.csrf
    assert one.csrf_matches(one.csrf)
    assert not one.csrf_matches(two.csrf)
    assert not one.csrf_matches("")
    assert not one.csrf_matches(one.csrf + "x")
    assert not ANONYMOUS.csrf_matches("")
    assert not Identity(operator=True, via="bearer").csrf_matches("")


def test_a_forged_or_garbled_cookie_is_anonymous() -> None:
    auth = OperatorAuth(TOKEN)
    session_id, _ = logged_in(auth)
    for cookie in [
        f"{COOKIE}=forged-{'a' * 40}",
        f"{COOKIE}={TOKEN}",
        f"{COOKIE}=",
        f"{COOKIE}={session_id}; {COOKIE}={session_id}",  # two: one was planted
        f"{COOKIE}=<script>{session_id}",
        f"other={session_id}",
        f"{COOKIE}={session_id}; pad=" + "p" * 9000,
    ]:
        assert auth.identify(headers(Cookie=cookie)) == ANONYMOUS, cookie[:60]
    good = auth.identify(headers(Cookie=f"theme=dark; {COOKIE}={session_id}; x=1"))
    assert good.operator


def test_a_session_expires_when_idle_and_at_its_lifetime() -> None:
    clock = Clock()
    auth = OperatorAuth(TOKEN, policy=Policy(idle=60, lifetime=300), clock=clock)
    session_id, _ = logged_in(auth)
    cookie = headers(Cookie=f"{COOKIE}={session_id}")
    for _ in range(5):  # used every 50 s: kept alive up to its lifetime
        clock.now += 50
        assert auth.identify(cookie).operator
    clock.now += 50  # 300 s old
    assert auth.identify(cookie) == ANONYMOUS
    session_id, _ = logged_in(auth)
    clock.now += 60
    assert auth.identify(headers(Cookie=f"{COOKIE}={session_id}")) == ANONYMOUS


def test_the_session_table_is_bounded_least_recently_used_first() -> None:
    auth = OperatorAuth(TOKEN, policy=Policy(max_sessions=3))
    first, _ = logged_in(auth)
    second, _ = logged_in(auth)
    logged_in(auth)
    assert auth.identify(headers(Cookie=f"{COOKIE}={first}")).operator  # used: kept
    logged_in(auth)
    assert auth.sessions == 3
    assert auth.identify(headers(Cookie=f"{COOKIE}={second}")) == ANONYMOUS
    assert auth.identify(headers(Cookie=f"{COOKIE}={first}")).operator


def test_logout_ends_the_session_and_clears_the_cookie() -> None:
    auth = OperatorAuth(TOKEN)
    session_id, _ = logged_in(auth)
    cookie = headers(Cookie=f"{COOKIE}={session_id}")
    cleared = auth.logout(cookie)
    assert cleared.startswith(f"{COOKIE}=;") and "Max-Age=0" in cleared
    assert auth.identify(cookie) == ANONYMOUS


# ---------------------------------------------------------------- login throttling


def test_wrong_logins_are_throttled_per_address_even_for_the_right_token() -> None:
    clock = Clock()
    auth = OperatorAuth(TOKEN, policy=Policy(guesses=3, window=100), clock=clock)
    for n in range(3):
        assert auth.login("10.0.0.9", f"guess-number-{n:04d}").refusal == "wrong"
        clock.now += 1
    refused = auth.login("10.0.0.9", TOKEN)
    assert refused.refusal == "throttled" and refused.cookie is None
    assert refused.retry_after == 97 and auth.blocked("10.0.0.9") == 97
    assert auth.login("10.0.0.10", TOKEN).cookie is not None  # another address is not held
    clock.now += 97  # the first guess aged out
    assert auth.blocked("10.0.0.9") == 0
    assert auth.login("10.0.0.9", TOKEN).cookie is not None


def test_bad_bearer_headers_count_as_guesses() -> None:
    auth = OperatorAuth(TOKEN, policy=Policy(guesses=2))
    auth.failed("10.0.0.7")
    auth.failed("10.0.0.7")
    assert auth.blocked("10.0.0.7") > 0
    assert auth.login("10.0.0.7", TOKEN).refusal == "throttled"


def test_the_failure_table_is_bounded() -> None:
    auth = OperatorAuth(TOKEN, policy=Policy(guesses=1, max_clients=10))
    for n in range(50):
        auth.login(f"10.0.1.{n}", "wrong-token-guess-0000")
    assert auth.blocked("10.0.1.49") > 0
    assert auth.blocked("10.0.1.0") == 0  # forgotten: the table holds 10


def test_without_a_token_nobody_logs_in() -> None:
    auth = OperatorAuth(None)
    assert auth.login("10.0.0.1", TOKEN).refusal == "disabled"
    assert not auth.token_matches(TOKEN) and not auth.enabled


def test_the_token_is_never_in_a_repr() -> None:
    auth = OperatorAuth(TOKEN)
    logged_in(auth)
    assert TOKEN not in repr(auth) and TOKEN not in str(vars(auth))


def test_session_cookie_parsing_is_bounded_and_strict() -> None:
    sid = "A" * 43
    assert session_cookie([f"{COOKIE}={sid}"]) == sid
    assert session_cookie(["a=b", f"{COOKIE}={sid}"]) == sid
    assert session_cookie([f"{COOKIE}={sid}" + " " * 9000]) is None
    assert session_cookie([f"{COOKIE}=short"]) is None
    assert session_cookie([]) is None


def test_an_own_token_file_that_is_a_symbolic_link_is_refused(tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    own_token(elsewhere, "a token")  # an owner-only file: read_token alone would take it
    link = tmp_path / "up" / "ui.token"
    link.parent.mkdir()
    link.symlink_to(elsewhere)
    with pytest.raises(CliError, match="is a symbolic link"):
        own_token(link, "up's operator token file")
