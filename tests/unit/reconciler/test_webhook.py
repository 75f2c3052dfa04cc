"""Push events judged, pure: github, gitlab, gitea and forgejo; signed, forged, other branches."""

from __future__ import annotations

import hashlib
import hmac
import json
from typing import Any

import pytest

from robotconf.reconciler.webhook import MAX_BODY, Answer, Outcome, judge, server_of

SECRET = b"7f3a9c0e1b2d4f6a8c0e2b4d6f8a1c3e"
HEAD = "0123456789abcdef0123456789abcdef01234567"


def push(ref: str = "refs/heads/main", **extra: Any) -> bytes:
    return json.dumps({"ref": ref, "after": HEAD, "repository": {"name": "lab"}, **extra}).encode()


def sign(body: bytes, secret: bytes = SECRET) -> str:
    return hmac.new(secret, body, hashlib.sha256).hexdigest()


def github(body: bytes, event: str = "push", **headers: str) -> list[tuple[str, str]]:
    """The headers GitHub sends (X-Hub-Signature-256 unless given or set to "")."""
    found = {
        "Content-Type": "application/json",
        "X-GitHub-Event": event,
        "X-GitHub-Delivery": "72d3162e-cc78-11e3-81ab-4c9367dc0958",
        "X-Hub-Signature-256": "sha256=" + sign(body),
        "User-Agent": "GitHub-Hookshot/044aadd",
        **headers,
    }
    return [(name, value) for name, value in found.items() if value != ""]


def gitlab(token: str, event: str = "Push Hook") -> list[tuple[str, str]]:
    return [
        ("Content-Type", "application/json"),
        ("X-Gitlab-Event", event),
        ("X-Gitlab-Token", token),
        ("X-Gitlab-Instance", "https://gitlab.lab"),
    ]


def gitea(body: bytes, event: str = "push") -> list[tuple[str, str]]:
    """What Gitea sends: its own headers, Gogs' and GitHub's, each signature in its form."""
    signature = sign(body)
    return [
        ("Content-Type", "application/json"),
        ("X-Gitea-Event", event),
        ("X-Gitea-Signature", signature),
        ("X-Gogs-Event", event),
        ("X-Gogs-Signature", signature),
        ("X-GitHub-Event", event),
        ("X-Hub-Signature-256", "sha256=" + signature),
    ]


def forgejo(
    body: bytes, event: str = "push", signature: str | None = None
) -> list[tuple[str, str]]:
    signature = sign(body) if signature is None else signature
    return [
        ("Content-Type", "application/json"),
        ("X-Forgejo-Event", event),
        ("X-Forgejo-Signature", signature),
        *gitea(body, event)[1:],
    ]


def answer(headers: list[tuple[str, str]], body: bytes, branch: str = "main") -> Answer:
    found = judge(headers, body, SECRET, branch)
    # Whatever the answer, it never holds the secret nor a signature, and it is one line.
    assert SECRET.decode() not in found.message
    assert sign(body) not in found.message and "\n" not in found.message
    return found


def test_a_signed_github_push_of_the_branch_fetches() -> None:
    body = push()
    found = answer(github(body), body)
    assert (found.code, found.outcome, found.server) == (200, Outcome.FETCH, "github")
    assert found.fetch
    assert found.message == f"push from github for main: fetching (commit {HEAD[:12]})"


def test_a_push_of_another_branch_or_a_tag_is_ignored() -> None:
    for ref, shown in [("refs/heads/dev", "dev"), ("refs/tags/v1.0", "refs/tags/v1.0")]:
        body = push(ref)
        found = answer(github(body), body)
        assert (found.code, found.outcome) == (202, Outcome.IGNORED)
        assert found.message == f"push from github for {shown} ignored: the reconciler follows main"
    body = push("refs/heads/main")
    assert answer(github(body), body, branch="release").code == 202


@pytest.mark.parametrize(
    ("signature", "code", "said"),
    [
        ("", 401, "no X-Hub-Signature-256 header"),
        ("sha256=" + "0" * 64, 403, "does not match"),
        ("sha256=" + sign(push(), b"another secret"), 403, "does not match"),
        ("sha1=" + "0" * 40, 403, "not an HMAC-SHA256 signature"),
        ("sha256=xyz", 403, "not an HMAC-SHA256 signature"),
        ("sha256=" + "é" * 64, 403, "not an HMAC-SHA256 signature"),
    ],
)
def test_a_github_push_without_the_right_signature_is_refused(
    signature: str, code: int, said: str
) -> None:
    body = push()
    found = answer(github(body, **{"X-Hub-Signature-256": signature}), body)
    assert (found.code, found.outcome, found.server) == (code, Outcome.REFUSED, "github")
    assert said in found.message


def test_the_signature_covers_the_body_byte_for_byte() -> None:
    body = push()
    headers = github(body)
    tampered = body.replace(b"main", b"mai\\u006e")  # the same JSON, other bytes
    assert json.loads(tampered) == json.loads(body)
    assert answer(headers, tampered).code == 403
    assert answer(headers, body + b" ").code == 403


def test_signature_digits_are_read_in_either_case() -> None:
    body = push()
    upper = "sha256=" + sign(body).upper()
    assert answer(github(body, **{"X-Hub-Signature-256": upper}), body).fetch


def test_events_other_than_push_are_answered_without_a_fetch_once_authenticated() -> None:
    body = json.dumps({"zen": "Keep it logically awesome.", "hook_id": 1}).encode()
    found = answer(github(body, event="ping"), body)
    assert (found.code, found.outcome) == (204, Outcome.IGNORED)
    assert found.message == "ping event from github: nothing to fetch"
    # A ping is authenticated like a push: nothing is said to whoever does not know the secret.
    assert answer(github(body, event="ping", **{"X-Hub-Signature-256": ""}), body).code == 401


@pytest.mark.parametrize(
    ("body", "said"),
    [
        (b'{"ref": "refs/heads/main"', "malformed JSON"),
        (b"ref=refs/heads/main", "malformed JSON"),
        (b"[1, 2]", "expected a JSON object"),
        (b'{"ref": "refs/heads/main", "ref": "refs/heads/dev"}', "duplicate key"),
        (b"\xff\xfe{}", "not UTF-8"),
        (b"[" * 100 + b"]" * 100, "levels deep"),
        (b'{"after": "x"}', "names no ref"),
        (b'{"ref": 7}', "names no ref"),
        (b"", "malformed JSON"),
    ],
)
def test_a_malformed_body_is_refused(body: bytes, said: str) -> None:
    found = answer(github(body), body)
    assert (found.code, found.outcome) == (400, Outcome.REFUSED)
    assert said in found.message


def test_a_body_over_the_limit_is_refused_before_anything_else() -> None:
    body = b" " * (MAX_BODY + 1)
    found = answer(github(body), body)
    assert (found.code, found.outcome) == (413, Outcome.REFUSED)
    assert found.message == f"the body is {MAX_BODY + 1:,} bytes, over the limit of {MAX_BODY:,}"
    # At the limit it is read (and here refused for what it is, not for its size).
    body = push() + b" " * (MAX_BODY - len(push()))
    assert answer(github(body), body).fetch


def test_a_form_encoded_body_is_refused_with_what_to_change() -> None:
    body = push()
    headers = github(body, **{"Content-Type": "application/x-www-form-urlencoded"})
    found = answer(headers, body)
    assert found.code == 415 and "set the webhook's content type to application/json" in (
        found.message
    )
    charset = github(body, **{"Content-Type": "application/json; charset=utf-8"})
    assert answer(charset, body).fetch


def test_a_request_of_no_known_git_server_is_refused() -> None:
    body = push()
    found = answer([("Content-Type", "application/json")], body)
    assert (found.code, found.server) == (400, "unknown")
    assert "X-GitHub-Event, X-Gitlab-Event, X-Gitea-Event, X-Forgejo-Event" in found.message


def test_a_header_given_twice_is_refused() -> None:
    body = push()
    twice = [*github(body), ("x-hub-signature-256", "sha256=" + "0" * 64)]
    found = answer(twice, body)
    assert found.code == 400 and "given twice" in found.message
    # Headers this module does not read may repeat.
    assert answer([*github(body), ("Accept", "*/*"), ("accept", "*/*")], body).fetch


def test_header_names_are_read_in_any_case() -> None:
    body = push()
    lower = [(name.lower(), value) for name, value in github(body)]
    assert answer(lower, body).fetch


def test_gitlab_sends_its_token_not_a_signature() -> None:
    body = push()
    found = answer(gitlab(SECRET.decode()), body)
    assert (found.code, found.server) == (200, "gitlab") and found.fetch
    assert found.message.startswith("push from gitlab for main: fetching")

    wrong = answer(gitlab("not the secret"), body)
    assert (wrong.code, wrong.outcome) == (403, Outcome.REFUSED)
    assert wrong.message == "the X-Gitlab-Token is not the secret of --webhook-secret-file"
    assert answer(gitlab(SECRET.decode()[:-1]), body).code == 403  # a prefix is not it
    assert answer(gitlab(SECRET.decode() + "x"), body).code == 403
    assert answer(gitlab("ψ" + SECRET.decode()), body).code == 403  # not even ISO-8859-1
    missing = [h for h in gitlab("") if h[0] != "X-Gitlab-Token"]
    assert answer(missing, body).code == 401

    tag = answer(gitlab(SECRET.decode(), event="Tag Push Hook"), push("refs/tags/v1"))
    assert (tag.code, tag.outcome) == (204, Outcome.IGNORED)
    other = answer(gitlab(SECRET.decode()), push("refs/heads/feature"))
    assert (other.code, other.outcome) == (202, Outcome.IGNORED)


def test_a_gitlab_token_is_compared_as_the_bytes_sent() -> None:
    """HTTP servers decode header values as ISO-8859-1: a UTF-8 token is those bytes."""
    secret = "sécret-ünïcode".encode()
    headers = gitlab(secret.decode("latin-1"))
    assert judge(headers, push(), secret, "main").fetch


def test_gitea_signs_with_a_hex_signature_and_sends_githubs_headers_too() -> None:
    body = push()
    found = answer(gitea(body), body)
    assert (found.code, found.server) == (200, "gitea") and found.fetch
    # Its own signature is the one checked: a forged one is refused whatever the others say.
    forged = [(n, "0" * 64 if n == "X-Gitea-Signature" else v) for n, v in gitea(body)]
    assert answer(forged, body).code == 403
    # Without its own, the X-Hub-Signature-256 it also sends will do.
    hub_only = [(n, v) for n, v in gitea(body) if n not in ("X-Gitea-Signature",)]
    assert answer(hub_only, body).fetch
    none = [(n, v) for n, v in gitea(body) if "Signature" not in n]
    refused = answer(none, body)
    assert refused.code == 401
    assert "no X-Gitea-Signature or X-Hub-Signature-256 header" in refused.message
    assert answer(gitea(body, event="issues"), body).code == 204


def test_forgejo_is_known_by_its_own_headers() -> None:
    body = push()
    found = answer(forgejo(body), body)
    assert (found.code, found.server) == (200, "forgejo") and found.fetch
    assert answer(forgejo(body, signature="f" * 64), body).code == 403
    assert answer(forgejo(body, signature="sha256=" + sign(body)), body).fetch
    wrong = answer(forgejo(push("refs/heads/dev")), push("refs/heads/dev"))
    assert (wrong.code, wrong.server) == (202, "forgejo")


def test_server_of_names_the_sender_for_refusals_made_before_judging() -> None:
    assert server_of(github(b"")) == "github"
    assert server_of(gitea(b"")) == "gitea"
    assert server_of(forgejo(b"")) == "forgejo"
    assert server_of(gitlab("x")) == "gitlab"
    assert server_of([("Accept", "*/*")]) == "unknown"


def test_what_the_request_says_is_printed_escaped() -> None:
    body = push("refs/heads/\x1b[31mred\nline")
    found = answer(github(body), body)
    assert found.code == 202 and "\\x1b[31mred\\nline" in found.message
    event = answer(github(b"{}", event="evil\x1b]0;title\x07"), b"{}")
    assert event.code == 204 and "\x1b" not in event.message
