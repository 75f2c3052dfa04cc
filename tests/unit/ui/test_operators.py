"""Named operators without sockets: a token's scrypt hash made, parsed and verified; the
operators file's lines, its errors (`FILE:LINE: what`), its bounds and its trust; an auth of
named operators: login with a name, Bearer NAME:TOKEN, the name in the session and in who
asks; the throttle's client keys (all of loopback one, a trusted proxy's X-Forwarded-For)."""

from __future__ import annotations

import email.message
from pathlib import Path

import pytest

from robotconf.contract.errors import CliError
from robotconf.workstation.ui.auth import OperatorAuth, Policy, refusal_text
from robotconf.workstation.ui.clients import LOOPBACK, client_of, parse_proxies
from robotconf.workstation.ui.operators import (
    MAX_OPERATORS,
    MIN_COST,
    HashError,
    Operators,
    hash_token,
    name_problem,
    parse_hash,
    parse_operators,
    read_operators,
)

ALICE = "alice-token-" + "a1" * 10
BOB = "bob-token-" + "b2" * 10
# Hashed once for the module, at the lowest cost a file may name: each costs ~16 MiB.
ALICE_HASH = hash_token(ALICE, MIN_COST).text()
BOB_HASH = hash_token(BOB, MIN_COST).text()
FILE = f"# the lab's operators\nalice {ALICE_HASH}\n\n  bob   {BOB_HASH}  \n"


def headers(**values: str) -> email.message.Message:
    message = email.message.Message()
    for name, value in values.items():
        message[name.replace("_", "-")] = value
    return message


def named(policy: Policy | None = None) -> OperatorAuth:
    return OperatorAuth(None, operators=parse_operators(FILE, "ops"), policy=policy)


# ---------------------------------------------------------------- the hash


def test_a_hash_verifies_its_token_alone_and_reads_back_as_written() -> None:
    made = hash_token(ALICE, MIN_COST)
    text = made.text()
    assert text.startswith(f"scrypt${MIN_COST}$8$1$") and ALICE not in text
    again = parse_hash(text)
    assert again == made and again.matches(ALICE)
    assert not again.matches(BOB) and not again.matches(ALICE + "x") and not again.matches("é")
    assert hash_token(ALICE, MIN_COST).text() != text  # a fresh salt each time
    assert repr(made) == f"TokenHash(cost={MIN_COST}, block=8, parallel=1)"


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("pbkdf2$1$1$1$AAAA$AAAA", "scrypt$N$r$p$SALT$HASH"),
        ("scrypt$16384$8$1$AAAA", "scrypt$N$r$p$SALT$HASH"),
        ("scrypt$x$8$1$AAAAAAAAAAA$" + "A" * 43, "whole numbers"),
        ("scrypt$1000$8$1$AAAAAAAAAAA$" + "A" * 43, "power of two"),
        ("scrypt$1024$8$1$AAAAAAAAAAA$" + "A" * 43, "power of two"),
        ("scrypt$2097152$8$1$AAAAAAAAAAA$" + "A" * 43, "power of two"),
        ("scrypt$16384$0$1$AAAAAAAAAAA$" + "A" * 43, "r is 1 to"),
        ("scrypt$1048576$32$16$AAAAAAAAAAA$" + "A" * 43, "MiB"),
        ("scrypt$16384$8$1$AA+A$" + "A" * 43, "base64"),
        ("scrypt$16384$8$1$AAAA$" + "A" * 43, "salt is at least 8 bytes"),
        ("scrypt$16384$8$1$AAAAAAAAAAA$AAAA", "salt is at least 8 bytes"),
        ("scrypt$" + "9" * 300, "at most 200"),
    ],
)
def test_a_bad_hash_says_what_is_wrong(text: str, said: str) -> None:
    with pytest.raises(HashError) as caught:
        parse_hash(text)
    assert said in str(caught.value)


def test_operator_names_follow_the_requester_rule_and_spare_the_single_tokens() -> None:
    for good in ["alice", "bob.smith", "o1", "a@lab", "x" * 32]:
        assert name_problem(good) is None, good
    for bad in ["", "-x", "a b", "a:b", "x" * 33, "é", "cookie", "Bearer"]:
        assert name_problem(bad) is not None, bad


# ---------------------------------------------------------------- the operators file


def test_the_operators_file_names_each_operator_with_their_hash() -> None:
    operators = parse_operators(FILE, "ops")
    assert sorted(operators.hashes) == ["alice", "bob"]
    assert operators.hashes["bob"].matches(BOB)
    assert ALICE_HASH not in repr(operators) and "alice" in repr(operators)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        (f"alice {ALICE_HASH}\nalice {BOB_HASH}\n", "ops:2: alice is named twice"),
        ("alice\n", "ops:1: a line is `NAME HASH`"),
        (f"alice {ALICE_HASH} extra\n", "ops:1: a line is `NAME HASH`"),
        (f"# c\nal:ice {ALICE_HASH}\n", "ops:2: 'al:ice' is not an operator name"),
        (f"bearer {ALICE_HASH}\n", "ops:1: 'bearer' is reserved"),
        ("alice scrypt$1$8$1$AAAAAAAAAAA$AAAA\n", "ops:1: N is a power of two"),
        (f"alice {ALICE}\n", "ops:1: a hash reads"),  # a token pasted for its hash
        ("# nobody yet\n", "ops: names no operator"),
    ],
    # Named, not numbered by their text: a hash's salt is new in each process, and pytest-xdist
    # needs every worker to collect the same test ids.
    ids=[
        "named-twice",
        "no-hash",
        "a-third-field",
        "a-bad-name",
        "a-reserved-name",
        "a-weak-hash",
        "a-token-for-its-hash",
        "nobody",
    ],
)
def test_a_bad_operators_file_says_where_and_what(text: str, said: str) -> None:
    with pytest.raises(CliError) as caught:
        parse_operators(text, "ops")
    assert said in caught.value.message and ALICE not in caught.value.message


def test_the_operators_file_is_bounded() -> None:
    lines = "".join(f"op{n} {ALICE_HASH}\n" for n in range(MAX_OPERATORS + 1))
    with pytest.raises(CliError, match=f"ops:{MAX_OPERATORS + 1}: more than {MAX_OPERATORS}"):
        parse_operators(lines, "ops")


def test_an_operators_file_others_may_change_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "operators"
    path.write_text(FILE, encoding="utf-8")
    path.chmod(0o644)  # others may read hashes, as ssh's known_hosts
    assert sorted(read_operators(path).hashes) == ["alice", "bob"]
    path.chmod(0o664)
    with pytest.raises(CliError, match=r"may be changed by others .*chmod go-w"):
        read_operators(path)
    with pytest.raises(CliError, match="cannot read --operators-file"):
        read_operators(tmp_path / "missing")
    (tmp_path / "big").write_bytes(b"#" * 70_000)
    with pytest.raises(CliError, match="over the limit"):
        read_operators(tmp_path / "big")
    (tmp_path / "binary").write_bytes(b"\xff\xfe")
    with pytest.raises(CliError, match="not UTF-8"):
        read_operators(tmp_path / "binary")


def test_one_token_and_named_operators_do_not_go_together(tmp_path: Path) -> None:
    ops = tmp_path / "operators"
    ops.write_text(FILE, encoding="utf-8")
    token = tmp_path / "token"
    token.write_text(ALICE + "\n", encoding="utf-8")
    token.chmod(0o600)
    with pytest.raises(CliError, match="do not go together"):
        OperatorAuth.from_file(token, operators_file=ops)
    assert OperatorAuth.from_file(None, operators_file=ops).named


# ---------------------------------------------------------------- named operators' auth


def test_each_operator_logs_in_with_their_name_and_token_and_is_named() -> None:
    auth = named()
    assert auth.enabled and auth.named
    for name, token in [("alice", ALICE), ("bob", BOB)]:
        login = auth.login("192.0.2.1", token, name)
        assert login.cookie is not None and login.name == name
        session = login.cookie.split(";")[0]
        who = auth.identify(headers(Cookie=session))
        assert who.operator and who.name == name and who.by == f"ui.{name}"
    assert auth.login("192.0.2.1", BOB, "alice").refusal == "wrong"  # bob's token, not alice's
    assert auth.login("192.0.2.1", ALICE, "carol").refusal == "wrong"  # nobody's name
    assert auth.login("192.0.2.1", ALICE, "").refusal == "wrong"
    wrong = refusal_text(auth.login("192.0.2.1", "x" * 20, "alice"), named=True)
    assert wrong == "That name and token are not an operator's."


def test_a_script_sends_bearer_name_colon_token() -> None:
    auth = named()
    who = auth.identify(headers(Authorization=f"Bearer bob:{BOB}"))
    assert who.operator and who.via == "bearer" and who.by == "ui.bob"
    again = auth.identify(headers(Authorization=f"Bearer bob:{BOB}"))  # remembered, no rehash
    assert again == who
    for bad in [f"Bearer {BOB}", f"Bearer alice:{BOB}", f"Bearer carol:{BOB}", "Bearer :"]:
        refused = auth.identify(headers(Authorization=bad))
        assert not refused.operator and refused.via == "bearer" and refused.name == ""


def test_the_single_token_still_says_how_it_came() -> None:
    auth = OperatorAuth("single-token-" + "s" * 10)
    assert not auth.named
    login = auth.login("192.0.2.1", "single-token-" + "s" * 10, "ignored")
    assert login.cookie is not None
    who = auth.identify(headers(Cookie=login.cookie.split(";")[0]))
    assert who.name == "" and who.by == "ui.cookie"
    bearer = auth.identify(headers(Authorization="Bearer single-token-" + "s" * 10))
    assert bearer.by == "ui.bearer"


def test_wrong_guesses_from_any_loopback_address_are_throttled_as_one() -> None:
    auth = named(Policy(guesses=3, window=60.0))
    for n in range(3):
        peer = f"127.0.0.{n + 1}"
        assert auth.login(auth.client(peer, headers()), "wrong-" + "w" * 20, "alice").refusal == (
            "wrong"
        )
    other = auth.client("127.9.9.9", headers())
    assert auth.login(other, ALICE, "alice").refusal == "throttled"
    assert auth.login(auth.client("::1", headers()), ALICE, "alice").refusal == "throttled"
    assert auth.login(auth.client("192.0.2.7", headers()), ALICE, "alice").cookie is not None
    # A throttled client's named Bearer is refused before it is hashed.
    refused = auth.identify(headers(Authorization=f"Bearer alice:{ALICE}"), "127.0.0.5")
    assert not refused.operator


# ---------------------------------------------------------------- client keys


def test_loopback_is_one_client_and_ipv6_a_slash_64() -> None:
    assert client_of("127.0.0.1", [], ()) == client_of("127.0.0.2", [], ()) == LOOPBACK
    assert client_of("::1", [], ()) == client_of("::ffff:127.0.0.3", [], ()) == LOOPBACK
    assert client_of("192.0.2.1", [], ()) == "192.0.2.1"
    assert client_of("2001:db8::1", [], ()) == client_of("2001:db8::2", [], ())
    assert client_of("not-an-address", [], ()) == "not-an-address"


def test_behind_a_trusted_proxy_the_last_untrusted_forwarded_hop_is_the_client() -> None:
    proxies = parse_proxies(["10.0.0.5", "10.1.0.0/16"])
    # The proxy appends who connected to it; what the client wrote before is not believed.
    assert client_of("10.0.0.5", ["198.51.100.7, 203.0.113.9"], proxies) == "203.0.113.9"
    assert client_of("10.0.0.5", ["203.0.113.9, 10.1.2.3"], proxies) == "203.0.113.9"
    assert client_of("10.0.0.5", ["203.0.113.9", "10.1.2.3"], proxies) == "203.0.113.9"
    assert client_of("10.0.0.5", ["127.0.0.7"], proxies) == LOOPBACK
    # No header, a garbled hop, a header too long: the proxy itself is the client.
    assert client_of("10.0.0.5", [], proxies) == "10.0.0.5"
    assert client_of("10.0.0.5", ["203.0.113.9, junk"], proxies) == "10.0.0.5"
    assert client_of("10.0.0.5", ["1.2.3.4," * 1000], proxies) == "10.0.0.5"
    # From anyone but a trusted proxy, the header is the client's own word: ignored.
    assert client_of("192.0.2.1", ["203.0.113.9"], proxies) == "192.0.2.1"
    assert client_of("127.0.0.1", ["203.0.113.9"], proxies) == LOOPBACK


def test_a_trusted_proxy_is_an_address_or_a_network() -> None:
    with pytest.raises(ValueError, match=r"--trusted-proxy .proxy\.lab. is not an IP address"):
        parse_proxies(["proxy.lab"])
    with pytest.raises(ValueError, match="more than 16"):
        parse_proxies([f"10.0.0.{n}" for n in range(17)])
    assert len(parse_proxies(["::1", "10.0.0.0/8"])) == 2


def test_an_operators_mapping_is_read_only() -> None:
    operators = parse_operators(FILE, "ops")
    assert isinstance(operators, Operators)
    with pytest.raises(TypeError):
        operators.hashes["eve"] = operators.hashes["alice"]  # type: ignore[index]
