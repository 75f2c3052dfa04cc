"""Who a request comes from: an operator or a viewer. The read side's stand-in (the write side
brings operator login): every request is an anonymous viewer; a token file is refused."""

from __future__ import annotations

import http.client
from dataclasses import dataclass
from pathlib import Path

from contract.errors import CliError


@dataclass(frozen=True)
class Identity:
    operator: bool
    csrf: str
    via: str  # "anonymous", "cookie" or "bearer"


ANONYMOUS = Identity(operator=False, csrf="", via="anonymous")


class OperatorAuth:
    """Tells operators from viewers by their request's headers."""

    def __init__(self, token: str | None = None) -> None:
        self._token = token

    @classmethod
    def from_file(cls, path: Path | None) -> OperatorAuth:
        """`--operator-token-file`: None gives a read-only UI."""
        if path is not None:
            raise CliError(
                f"--operator-token-file {path}: operator login arrives with the write side"
            )
        return cls()

    def identify(self, headers: http.client.HTTPMessage) -> Identity:
        return ANONYMOUS
