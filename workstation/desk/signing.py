"""The key the desk signs its requests with (restarts, rollout decisions), read once at start:
a key that cannot be read is a one-line error, before anything is sent."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from robotconf.contract.errors import CliError, ExitCode

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey


def private_key(path: Path | None) -> Ed25519PrivateKey | None:
    """The key restarts are signed with, if one is given; a key that cannot be read is a
    one-line error."""
    if path is None:
        return None
    from robotconf.contract.signing import SigningKeyError, load_private_key

    try:
        return load_private_key(path)
    except SigningKeyError as exc:
        raise CliError(str(exc), ExitCode.TOOL) from None
