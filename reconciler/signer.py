"""The reconciler's signer: a private key file made into a function that signs requests."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from robotconf.contract.signing import Signed

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

    from robotconf.reconciler.delivery import Signer


def make_signer(key_path: Path | None) -> Signer | None:
    """A function that signs launch and stop requests with the key, or None when signing is off;
    raises SigningKeyError when the key cannot be read."""
    if key_path is None:
        return None
    from robotconf.contract.signing import load_private_key, sign

    key = load_private_key(key_path)

    def signer(request: Signed) -> Signed:
        return sign(request, key)

    return signer


def make_verifier(key_path: Path | None) -> Ed25519PublicKey | None:
    """The public half of the signing key: operators' rollout actions must be signed with it
    when the lab signs (None: signing is off, the broker's ACL alone says who may act)."""
    if key_path is None:
        return None
    from robotconf.contract.signing import load_private_key

    return load_private_key(key_path).public_key()
