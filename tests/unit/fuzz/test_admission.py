"""Property: the agent's admission decides every payload — and nothing altered passes as signed."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey
from hypothesis import given
from hypothesis import strategies as st

from robotconf.agent.admission import Accept, Freshness, Reject, interpret
from robotconf.contract.signing import (
    generate_keys,
    load_private_key,
    load_public_key,
    sign,
    verify_object,
)
from robotconf.contract.wire import RobotDescription
from tests.support.agents import make_request
from tests.unit.fuzz.strategies import json_values, mutated

ROBOT = RobotDescription(id="tb3-01", platform="ROS2", recommended_template="turtlebot3-camera")


def _key_pair() -> tuple[Ed25519PrivateKey, Ed25519PublicKey]:
    """A signing key pair kept in memory: its files are removed once read."""
    with tempfile.TemporaryDirectory(prefix="robotconf-fuzz-keys-") as folder:
        keys = generate_keys(Path(folder))
        return load_private_key(keys.private), load_public_key(keys.public)


PRIVATE, PUBLIC = _key_pair()
SIGNED = sign(make_request(), PRIVATE, issued_at=1_700_000_000.0)


def check_signature(data: dict[str, Any]) -> str | None:
    return verify_object(data, PUBLIC)


@given(st.binary(max_size=400))
def test_any_bytes_get_a_verdict(payload: bytes) -> None:
    interpret(payload, ROBOT)
    interpret(payload, ROBOT, check_signature, Freshness(1_700_000_000.0, None))


@given(st.dictionaries(st.text(max_size=12), json_values, max_size=6))
def test_any_object_gets_a_verdict(extra: dict[str, Any]) -> None:
    data = json.loads(SIGNED.payload())
    data.update(extra)
    payload = json.dumps(data).encode()
    verdict = interpret(payload, ROBOT, check_signature)
    if isinstance(verdict, Accept):
        # Only a no-op update can still verify.
        assert verdict.request == SIGNED


@given(mutated(SIGNED.payload()))
def test_an_altered_signed_request_is_never_accepted_as_something_else(payload: bytes) -> None:
    verdict = interpret(payload, ROBOT, check_signature)
    if isinstance(verdict, Accept):
        assert verdict.request == SIGNED
    else:
        assert isinstance(verdict, Reject) or payload.strip() == b""


@given(
    st.floats(allow_nan=True, allow_infinity=True)
    | st.integers(min_value=-(2**80), max_value=2**80),
    st.text(max_size=100),
)
def test_any_signing_fields(issued_at: Any, signature: str) -> None:
    data = json.loads(SIGNED.payload())
    data["issued_at"], data["signature"] = issued_at, signature
    try:
        payload = json.dumps(data, allow_nan=True).encode()
    except ValueError:
        return
    verdict = interpret(payload, ROBOT, check_signature, Freshness(1_700_000_000.0, "sha256:x"))
    assert not isinstance(verdict, Accept) or verdict.request == SIGNED
