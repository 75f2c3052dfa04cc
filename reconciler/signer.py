"""The reconciler's signer: a private key file made into a function that signs requests."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from contract.signing import Signed

if TYPE_CHECKING:
    from reconciler.controller import Signer


def make_signer(key_path: Path | None) -> Signer | None:
    """A function that signs launch and stop requests with the key, or None when signing is off;
    raises SigningKeyError when the key cannot be read."""
    if key_path is None:
        return None
    from contract.signing import load_private_key, sign

    key = load_private_key(key_path)

    def signer(request: Signed) -> Signed:
        return sign(request, key)

    return signer
