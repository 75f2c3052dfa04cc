"""Push events of git servers judged, pure: is this request a push of our branch, signed with
our secret? GitHub, GitLab, Gitea and Forgejo; `reconciler/webhook_server.py` is the HTTP edge.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from robotconf.contract.safejson import PayloadError, parse_object
from robotconf.contract.textsafe import printable
from robotconf.contract.wire import is_commit

# A push of a few commits is a few kB (GitHub lists at most 20 commits in one); the repository
# and sender blocks add a few more. A megabyte is generous, and small enough to hold in memory.
MAX_BODY = 1024 * 1024

_SIGNATURE = re.compile(r"(?:sha256=)?([0-9a-fA-F]{64})")


@dataclass(frozen=True)
class GitServer:
    """How one kind of git server says what happened and proves it knows the secret."""

    name: str
    event_header: str
    push_event: str
    proof_headers: tuple[str, ...]  # by preference: the first one present is checked
    token: bool = False  # the proof is the secret itself (GitLab), not an HMAC of the body


# Forgejo sends its own headers and Gitea's and GitHub's too, Gitea its own and GitHub's: the
# most specific name is looked for first.
SERVERS = (
    GitServer(
        "forgejo",
        "X-Forgejo-Event",
        "push",
        ("X-Forgejo-Signature", "X-Gitea-Signature", "X-Hub-Signature-256"),
    ),
    GitServer("gitea", "X-Gitea-Event", "push", ("X-Gitea-Signature", "X-Hub-Signature-256")),
    GitServer("gitlab", "X-Gitlab-Event", "Push Hook", ("X-Gitlab-Token",), token=True),
    GitServer("github", "X-GitHub-Event", "push", ("X-Hub-Signature-256",)),
)
UNKNOWN = "unknown"
_READ = {
    name.lower() for server in SERVERS for name in (server.event_header, *server.proof_headers)
} | {"content-type"}


class Outcome(enum.Enum):
    FETCH = "fetch"  # a push of the branch: fetch and reconcile now
    IGNORED = "ignored"  # genuine, but nothing to do: another branch, another event
    REFUSED = "refused"  # not genuine or not readable


@dataclass(frozen=True)
class Answer:
    """The HTTP answer to one request, and what it means; `message` is one printable line for
    the log and the response body, and never holds the secret or a signature."""

    code: int
    outcome: Outcome
    server: str  # one of SERVERS' names, or "unknown"
    message: str

    @property
    def fetch(self) -> bool:
        return self.outcome is Outcome.FETCH


def refused(code: int, server: str, message: str) -> Answer:
    return Answer(code, Outcome.REFUSED, server, message)


def _shown(text: str, limit: int = 100) -> str:
    """Text from the request, made printable and short."""
    return printable(text[:limit]) + ("…" if len(text) > limit else "")


def _headers(pairs: Iterable[tuple[str, str]]) -> dict[str, str] | str:
    """The headers this module reads, by lower-case name; the name of one given twice (two
    values would leave it to chance which one was checked) instead."""
    found: dict[str, str] = {}
    for name, value in pairs:
        key = name.strip().lower()
        if key not in _READ:
            continue
        if key in found:
            return name.strip()
        found[key] = value.strip()
    return found


def server_of(headers: Iterable[tuple[str, str]]) -> str:
    """Which kind of git server the request says it comes from (or "unknown")."""
    names = {name.strip().lower() for name, _ in headers}
    return next((s.name for s in SERVERS if s.event_header.lower() in names), UNKNOWN)


def judge(headers: Iterable[tuple[str, str]], body: bytes, secret: bytes, branch: str) -> Answer:
    """The answer to one POST. `headers` are (name, value) pairs as received (values decoded as
    ISO-8859-1, as HTTP servers do); `secret` is --webhook-secret-file's content.

    In this order, so that nothing unauthenticated is parsed: size, which server, its proof
    (constant-time), the event, the content type, the JSON body, its `ref`."""
    if len(body) > MAX_BODY:
        return refused(
            413, UNKNOWN, f"the body is {len(body):,} bytes, over the limit of {MAX_BODY:,}"
        )
    found = _headers(headers)
    if isinstance(found, str):
        return refused(400, UNKNOWN, f"the header {_shown(found)} is given twice")
    server = next((s for s in SERVERS if s.event_header.lower() in found), None)
    if server is None:
        return refused(
            400,
            UNKNOWN,
            "not an event of GitHub, GitLab, Gitea or Forgejo: none of the headers "
            + ", ".join(s.event_header for s in reversed(SERVERS)),
        )
    problem = _authenticate(server, found, body, secret)
    if problem is not None:
        return problem
    event = found[server.event_header.lower()]
    if event != server.push_event:
        return Answer(
            204,
            Outcome.IGNORED,
            server.name,
            f"{_shown(event, 40)} event from {server.name}: nothing to fetch",
        )
    media = found.get("content-type", "application/json").split(";")[0].strip().lower()
    if media != "application/json":
        return refused(
            415,
            server.name,
            f"the body is {_shown(media, 60)}, not application/json: set the webhook's "
            "content type to application/json",
        )
    try:
        payload = parse_object(body, max_bytes=MAX_BODY)
    except PayloadError as exc:
        return refused(
            400, server.name, f"the push's body is not a JSON object: {_shown(str(exc))}"
        )
    return _judge_push(server.name, payload, branch)


def _authenticate(
    server: GitServer, found: dict[str, str], body: bytes, secret: bytes
) -> Answer | None:
    """None when the request proves it knows the secret; the refusal otherwise."""
    header = next((h for h in server.proof_headers if h.lower() in found), None)
    if header is None:
        return refused(
            401,
            server.name,
            f"no {' or '.join(server.proof_headers)} header: give the webhook the secret of "
            "--webhook-secret-file",
        )
    given = found[header.lower()]
    if server.token:
        try:
            token = given.encode("latin-1")  # back to the bytes that came over the wire
        except UnicodeEncodeError:
            token = b""
        # Hashed first, so that not even the secret's length shows in the comparison's time.
        same = hmac.compare_digest(hashlib.sha256(token).digest(), hashlib.sha256(secret).digest())
        if not same:
            return refused(
                403, server.name, f"the {header} is not the secret of --webhook-secret-file"
            )
        return None
    signature = _SIGNATURE.fullmatch(given)
    if signature is None:
        return refused(
            403,
            server.name,
            f"the {header} header is not an HMAC-SHA256 signature (64 hexadecimal digits)",
        )
    expected = hmac.new(secret, body, hashlib.sha256).hexdigest().encode()
    if not hmac.compare_digest(expected, signature.group(1).lower().encode()):
        return refused(
            403,
            server.name,
            f"the {header} signature does not match the body signed with the secret of "
            "--webhook-secret-file",
        )
    return None


def _judge_push(server: str, payload: dict[str, Any], branch: str) -> Answer:
    ref = payload.get("ref")
    if not isinstance(ref, str) or not ref:
        return refused(400, server, "the push names no ref (a `ref` text such as refs/heads/main)")
    if ref != f"refs/heads/{branch}":
        return Answer(
            202,
            Outcome.IGNORED,
            server,
            f"push from {server} for {_shown(ref.removeprefix('refs/heads/'))} ignored: "
            f"the reconciler follows {branch}",
        )
    after = payload.get("after")
    commit = f" (commit {after[:12]})" if isinstance(after, str) and is_commit(after) else ""
    return Answer(200, Outcome.FETCH, server, f"push from {server} for {branch}: fetching{commit}")
