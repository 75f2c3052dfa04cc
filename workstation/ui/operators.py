"""Named operators: the hash a token is kept as (`robotconf hash-token`), and the operators file
of `robotconf ui --operators-file` (one `NAME HASH` a line), parsed and checked.

A token is kept as `scrypt$N$r$p$SALT$HASH` (hashlib's scrypt, salt and hash in unpadded
urlsafe base64): memory-hard, stdlib only, verified in constant time. Parsing is pure; reading
the file is `read_operators`, one small function (the shared trust rule, contract/trust.py)."""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import re
import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from robotconf.contract.errors import CliError
from robotconf.contract.trust import Trust, UntrustedFile, read_trusted

SCHEME = "scrypt"
COST = 2**15  # scrypt's N: about 32 MiB and a tenth of a second a guess
BLOCK = 8  # r
PARALLEL = 1  # p
MIN_COST = 2**14
MAX_COST = 2**20
MAX_BLOCK = 32
MAX_PARALLEL = 16
MAX_MEMORY = 256 * 1024 * 1024  # what one verify may take: 128 * N * r * p bytes
SALT_BYTES = 16
HASH_BYTES = 32
MAX_HASH_TEXT = 200
MAX_OPERATORS = 100
MAX_OPERATORS_FILE = 64 * 1024
MAX_NAME = 32
# A name joins `ui.` in a restart's requested_by (contract/launch.py REQUESTER_PATTERN): the
# same characters, fewer of them.
_NAME = re.compile(rf"[A-Za-z0-9][A-Za-z0-9_.@+-]{{0,{MAX_NAME - 1}}}")
# The single token's operator is `ui.cookie` / `ui.bearer`: no named operator may pose as one.
RESERVED = frozenset({"cookie", "bearer", "anonymous"})
_B64 = re.compile(r"[A-Za-z0-9_-]+")


class HashError(ValueError):
    """A hash text that is not one of ours: its message says what is wrong."""


@dataclass(frozen=True)
class TokenHash:
    """One token's scrypt hash and its parameters."""

    cost: int
    block: int
    parallel: int
    salt: bytes = field(repr=False)
    digest: bytes = field(repr=False)

    def text(self) -> str:
        salt, digest = _b64(self.salt), _b64(self.digest)
        return f"{SCHEME}${self.cost}${self.block}${self.parallel}${salt}${digest}"

    def matches(self, token: str) -> bool:
        """True when `token` is the one hashed (its hash compared in constant time)."""
        try:
            candidate = token.encode("ascii")
        except UnicodeEncodeError:
            candidate = b"\x00"  # hashed anyway: a refusal takes as long as a match
        computed = _scrypt(candidate, self.salt, self.cost, self.block, self.parallel)
        return hmac.compare_digest(computed, self.digest)


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).decode("ascii").rstrip("=")


def _unb64(text: str) -> bytes:
    if not _B64.fullmatch(text):
        raise HashError("the salt and hash are urlsafe base64")
    try:
        return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))
    except (binascii.Error, ValueError):
        raise HashError("the salt and hash are urlsafe base64") from None


def _scrypt(token: bytes, salt: bytes, cost: int, block: int, parallel: int) -> bytes:
    memory = 128 * cost * block * parallel + 1024 * 1024
    return hashlib.scrypt(
        token, salt=salt, n=cost, r=block, p=parallel, maxmem=memory, dklen=HASH_BYTES
    )


def hash_token(token: str, cost: int = COST) -> TokenHash:
    """A new hash of `token` (a fresh random salt each time)."""
    salt = secrets.token_bytes(SALT_BYTES)
    digest = _scrypt(token.encode("ascii"), salt, cost, BLOCK, PARALLEL)
    return TokenHash(cost, BLOCK, PARALLEL, salt, digest)


def parse_hash(text: str) -> TokenHash:
    """`scrypt$N$r$p$SALT$HASH` as a TokenHash; HashError saying what is wrong, its bounds
    checked before any memory is spent on it."""
    if len(text) > MAX_HASH_TEXT:
        raise HashError(f"a hash is at most {MAX_HASH_TEXT} characters")
    parts = text.split("$")
    if len(parts) != 6 or parts[0] != SCHEME:
        raise HashError(f"a hash reads {SCHEME}$N$r$p$SALT$HASH (as robotconf hash-token prints)")
    if not all(part.isdigit() and len(part) <= 8 for part in parts[1:4]):
        raise HashError("N, r and p are whole numbers")
    cost, block, parallel = (int(part) for part in parts[1:4])
    if cost & (cost - 1) or not MIN_COST <= cost <= MAX_COST:
        raise HashError(f"N is a power of two from {MIN_COST} to {MAX_COST}")
    if not (1 <= block <= MAX_BLOCK and 1 <= parallel <= MAX_PARALLEL):
        raise HashError(f"r is 1 to {MAX_BLOCK}, p 1 to {MAX_PARALLEL}")
    if 128 * cost * block * parallel > MAX_MEMORY:
        raise HashError(f"N * r * p takes more than {MAX_MEMORY // 2**20} MiB to verify")
    salt, digest = _unb64(parts[4]), _unb64(parts[5])
    if len(salt) < 8 or len(digest) != HASH_BYTES:
        raise HashError(f"the salt is at least 8 bytes and the hash {HASH_BYTES}")
    return TokenHash(cost, block, parallel, salt, digest)


def name_problem(name: str) -> str | None:
    """Why `name` may not name an operator, else None."""
    if not _NAME.fullmatch(name):
        return (
            f"{name[:40]!r} is not an operator name: letters, digits and . _ @ + - "
            f"(at most {MAX_NAME}), starting with a letter or digit"
        )
    if name.lower() in RESERVED:
        return f"{name!r} is reserved (the single token's operator is ui.{name.lower()})"
    return None


@dataclass(frozen=True)
class Operators:
    """The operators of an operators file, by name."""

    hashes: Mapping[str, TokenHash]

    def __repr__(self) -> str:  # names only, never a hash
        return f"Operators({sorted(self.hashes)})"


def parse_operators(text: str, where: str) -> Operators:
    """The operators in an operators file's text; CliError `WHERE:LINE: what is wrong` at the
    first bad line. Blank lines and `#` comments are skipped; names are unique."""
    hashes: dict[str, TokenHash] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        at = f"{where}:{number}"
        fields = line.split()
        if len(fields) != 2:
            raise CliError(f"{at}: a line is `NAME HASH` (the hash robotconf hash-token prints)")
        name, hash_text = fields
        problem = name_problem(name)
        if problem is not None:
            raise CliError(f"{at}: {problem}")
        if name in hashes:
            raise CliError(f"{at}: {name} is named twice: one line per operator")
        try:
            hashes[name] = parse_hash(hash_text)
        except HashError as exc:
            raise CliError(f"{at}: {exc}") from None
        if len(hashes) > MAX_OPERATORS:
            raise CliError(f"{at}: more than {MAX_OPERATORS} operators")
    if not hashes:
        raise CliError(f"{where}: names no operator (lines `NAME HASH`, from robotconf hash-token)")
    return Operators(MappingProxyType(hashes))


def read_operators(path: Path) -> Operators:
    """The operators file at `path`, once the shared trust rule passed it (yours or root's,
    nobody else may change it; the hashes need not be secret); CliError otherwise."""
    where = f"--operators-file {path}"
    try:
        data = read_trusted(path, Trust.CONFIG, MAX_OPERATORS_FILE)
    except UntrustedFile as exc:
        raise CliError(f"{where} {exc}") from None
    except OSError as exc:
        raise CliError(f"cannot read {where}: {exc.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise CliError(f"{where}: is not UTF-8 text") from None
    return parse_operators(text, str(path))
