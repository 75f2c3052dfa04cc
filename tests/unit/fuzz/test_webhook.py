"""Property: every webhook request gets an answer — and only a request signed with the secret
fetches; nothing altered after signing does."""

from __future__ import annotations

import hashlib
import hmac
import json

from hypothesis import given
from hypothesis import strategies as st

from robotconf.reconciler.webhook import SERVERS, Outcome, judge
from tests.unit.fuzz.strategies import json_values, mutated

SECRET = b"s3cret-for-the-fuzzer"
CODES = {400, 401, 403, 413, 415}
NAMES = sorted(
    {n for s in SERVERS for n in (s.event_header, *s.proof_headers)}
    | {"Content-Type", "X-Gogs-Event", "User-Agent"}
)
VALUES = st.one_of(
    st.sampled_from(["push", "Push Hook", "ping", "application/json", "sha256=", ""]),
    st.text(max_size=80),
    st.text(alphabet="0123456789abcdef", min_size=64, max_size=64).map(lambda h: "sha256=" + h),
)
HEADERS = st.lists(
    st.tuples(st.one_of(st.sampled_from(NAMES), st.text(max_size=20)), VALUES), max_size=8
)
BODIES = st.one_of(
    st.binary(max_size=300),
    json_values.map(lambda v: json.dumps(v).encode()),
    st.sampled_from([b'{"ref": "refs/heads/main"}', b'{"ref": "refs/heads/dev"}']),
)


@given(HEADERS, BODIES)
def test_anything_gets_an_answer_and_nothing_unsigned_fetches(
    headers: list[tuple[str, str]], body: bytes
) -> None:
    """Values drawn without the secret: no proof can be right (a gitlab token included)."""
    answer = judge(headers, body, SECRET, "main")
    assert answer.code in CODES
    assert answer.outcome is Outcome.REFUSED  # not even "ignored": that says it was genuine
    assert "\n" not in answer.message and SECRET.decode() not in answer.message


ORIGINAL = json.dumps({"ref": "refs/heads/main", "after": "0" * 40}).encode()
SIGNATURE = hmac.new(SECRET, ORIGINAL, hashlib.sha256).hexdigest()
SIGNED = st.sampled_from(
    [
        [(server.event_header, "push"), (header, "sha256=" + SIGNATURE)]
        for server in SERVERS
        if not server.token
        for header in server.proof_headers
    ]
)


@given(SIGNED, mutated(ORIGINAL))
def test_a_body_altered_after_signing_never_fetches(
    headers: list[tuple[str, str]], body: bytes
) -> None:
    assert judge(headers, ORIGINAL, SECRET, "main").fetch  # the unaltered one does
    answer = judge(headers, body, SECRET, "main")
    assert answer.fetch == (body == ORIGINAL)
    if body != ORIGINAL:
        assert (answer.code, answer.outcome) == (403, Outcome.REFUSED)
