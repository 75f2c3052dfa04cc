"""Signed Launch Requests: Ed25519 keys, signing by the reconciler, verification by the agent.

The signature covers the canonical request with everything but the signature itself: robot id,
revision, digest, issued_at and the content. `cryptography` is imported only here, and only
when a key is used, so an agent without signing imports nothing more.
"""

from __future__ import annotations

import base64
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from robotconf.contract.files import write_atomic
from robotconf.contract.launch import (
    LaunchRequest,
    RestartRequest,
    RolloutAction,
    StopRequest,
    canonical_json,
)
from robotconf.contract.trust import Trust, UntrustedFile, read_trusted

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import (
        Ed25519PrivateKey,
        Ed25519PublicKey,
    )

Signed = TypeVar("Signed", LaunchRequest, StopRequest, RestartRequest, RolloutAction)

PRIVATE_NAME = "launch-signing.key"
PUBLIC_NAME = "launch-signing.pub"


class SigningKeyError(Exception):
    """A key file is missing, unreadable or not an Ed25519 key."""


@dataclass(frozen=True)
class KeyPair:
    private: Path
    public: Path


def _require_cryptography() -> None:
    """A robot-only install has no `cryptography` unless asked for: say which extra brings it."""
    import importlib.util

    if importlib.util.find_spec("cryptography") is None:
        raise SigningKeyError(
            "signed Launch Requests need the `cryptography` package, which this install lacks: "
            "pip install 'robotconf[signing]' (on a robot) or 'robotconf[server]'"
        )


def generate_keys(folder: Path, *, force: bool = False) -> KeyPair:
    """Write a new Ed25519 pair: the private key 0600, the public key 0644."""
    _require_cryptography()
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    pair = KeyPair(folder / PRIVATE_NAME, folder / PUBLIC_NAME)
    if not force and (pair.private.exists() or pair.public.exists()):
        raise SigningKeyError(f"{folder} already holds a key pair; pass --force to replace it")
    folder.mkdir(parents=True, exist_ok=True)
    key = Ed25519PrivateKey.generate()
    private_pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    public_pem = key.public_key().public_bytes(
        serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
    )
    # Created with its final mode: a secret is never briefly world-readable.
    write_atomic(pair.private, private_pem, 0o600)
    write_atomic(pair.public, public_pem, 0o644)
    return pair


MAX_KEY_FILE = 64 * 1024  # a PEM Ed25519 key is a few hundred bytes


def load_private_key(path: Path) -> Ed25519PrivateKey:
    _require_cryptography()
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    try:
        key = serialization.load_pem_private_key(
            read_trusted(path, Trust.SECRET, MAX_KEY_FILE), password=None
        )
    except UntrustedFile as exc:
        raise SigningKeyError(f"signing key {path} {exc}") from None
    except OSError as exc:
        raise SigningKeyError(f"{path}: cannot read the signing key ({exc.strerror})") from None
    except (ValueError, TypeError):
        raise SigningKeyError(
            f"{path}: not a PEM private key (make one: robotconf keys generate)"
        ) from None
    if not isinstance(key, Ed25519PrivateKey):
        raise SigningKeyError(f"{path}: not an Ed25519 key (make one: robotconf keys generate)")
    return key


def load_public_key(path: Path) -> Ed25519PublicKey:
    _require_cryptography()
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

    try:
        # Not a secret, but whoever may change it decides which requests the agent obeys.
        key = serialization.load_pem_public_key(read_trusted(path, Trust.CONFIG, MAX_KEY_FILE))
    except UntrustedFile as exc:
        raise SigningKeyError(f"public key {path} {exc}") from None
    except OSError as exc:
        raise SigningKeyError(f"{path}: cannot read the public key ({exc.strerror})") from None
    except ValueError:
        raise SigningKeyError(
            f"{path}: not a PEM public key (robotconf keys generate writes one)"
        ) from None
    if not isinstance(key, Ed25519PublicKey):
        raise SigningKeyError(f"{path}: not an Ed25519 public key")
    return key


def signed_bytes(
    request: LaunchRequest | StopRequest | RestartRequest | RolloutAction,
) -> bytes:
    return canonical_json(request.wire(signature=False))


def sign(request: Signed, key: Ed25519PrivateKey, issued_at: float | None = None) -> Signed:
    """The request (a launch, a stop or a restart) stamped with `issued_at`, signed over all of
    it."""
    stamped = request.model_copy(
        update={
            "issued_at": round(time.time() if issued_at is None else issued_at, 6),
            "signature": None,
        }
    )
    signature = base64.b64encode(key.sign(signed_bytes(stamped))).decode("ascii")
    return stamped.model_copy(update={"signature": signature})


def verify(
    request: LaunchRequest | StopRequest | RestartRequest | RolloutAction, key: Ed25519PublicKey
) -> str | None:
    """None when the reconciler's key signed exactly this request, else why not."""
    return verify_object(request.wire(), key)


# A signature is 64 bytes; anything much longer is not one, and is not decoded.
_MAX_SIGNATURE_CHARS = 128


def verify_object(data: dict[str, Any], key: Ed25519PublicKey) -> str | None:
    """None when the fleet's key signed exactly this parsed request (a launch, a stop or a
    restart), else why not. Works on the plain JSON object, so nothing else of it is trusted,
    or even built, before its signature is known to be good."""
    from cryptography.exceptions import InvalidSignature

    # Only the wording of the answer: whatever `kind` says is not trusted for anything else.
    what = "restart" if data.get("kind") == "Restart" else "request"
    signature, issued_at = data.get("signature"), data.get("issued_at")
    if signature is None or issued_at is None:
        return f"{what} is not signed, and this agent requires signed requests"
    if not isinstance(signature, str) or len(signature) > _MAX_SIGNATURE_CHARS:
        return "signature is not a base64 Ed25519 signature"
    if isinstance(issued_at, bool) or not isinstance(issued_at, (int, float)):
        return "issued_at is not a number"
    try:
        raw = base64.b64decode(signature, validate=True)
    except ValueError:
        return "signature is not valid base64"
    unsigned = {k: v for k, v in data.items() if k != "signature"}
    try:
        key.verify(raw, canonical_json(unsigned))
    except (InvalidSignature, ValueError):
        return f"signature does not verify: the {what} was altered or signed by another key"
    return None
