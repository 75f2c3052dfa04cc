"""Who a UI request comes from: an operator (the one token of --operator-token-file, or a named
operator's own token of --operators-file, as a Bearer header or a login session's cookie) or a
viewer; sessions, CSRF tokens and login throttling."""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import os
import re
import secrets
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol

from robotconf.contract.errors import CliError
from robotconf.contract.trust import Trust, UntrustedFile, read_trusted
from robotconf.workstation.ui.clients import Network, client_of
from robotconf.workstation.ui.operators import (
    COST,
    Operators,
    TokenHash,
    hash_token,
    name_problem,
    read_operators,
)

COOKIE = "robotconf_ui"
MIN_TOKEN = 16
MAX_TOKEN = 1024
MAX_TOKEN_FILE = 64 * 1024  # bounds the read; the token itself is checked after
# Visible ASCII: the token fits a header and a form field as it is.
_TOKEN = re.compile(r"[\x21-\x7e]+")
_SESSION_ID = re.compile(r"[A-Za-z0-9_-]{20,100}")
MAX_COOKIE_HEADER = 8192
MAX_VERIFIED = 64  # named operators' Bearer credentials remembered once verified


class Headers(Protocol):
    """What identify reads of a request's headers (http.client.HTTPMessage has it)."""

    def get_all(self, name: str, failobj: None = None) -> list[str] | None: ...


Via = Literal["anonymous", "cookie", "bearer"]


@dataclass(frozen=True)
class Identity:
    """Who asks. `via` says how they came: with no credentials, a session cookie, or a Bearer
    header. A bad Bearer token is `via="bearer"` without `operator` (refused, 403); an unknown
    or expired cookie is anonymous (log in again, 401)."""

    operator: bool
    csrf: str = field(default="", repr=False)  # the session's; empty for a Bearer or a viewer
    via: Via = "anonymous"
    name: str = ""  # a named operator's (--operators-file); empty for the single token's

    @property
    def by(self) -> str:
        """Who asks, as a restart's or a decision's requested_by says it (and the status and
        the timeline show it): `ui.NAME` for a named operator, else `ui.cookie` / `ui.bearer`."""
        return f"ui.{self.name}" if self.name else f"ui.{self.via}"

    def csrf_matches(self, given: str) -> bool:
        """True when `given` is this session's CSRF token (compared in constant time)."""
        if not self.csrf:
            return False
        return hmac.compare_digest(self.csrf.encode("utf-8"), given.encode("utf-8", "replace"))


ANONYMOUS = Identity(operator=False)


@dataclass(frozen=True)
class Policy:
    """The bounds of the session table and of login guesses."""

    max_sessions: int = 256  # beyond, the least recently used session ends
    idle: float = 3600.0  # seconds a session lasts unused
    lifetime: float = 12 * 3600.0  # seconds a session lasts at most
    guesses: int = 5  # failed logins per client address within `window`...
    window: float = 300.0  # ...after which that address may not try until the oldest ages out
    max_clients: int = 4096  # addresses whose failures are remembered


@dataclass
class _Session:
    csrf: str
    created: float
    used: float
    name: str = ""


def read_token(path: Path, what: str = "--operator-token-file", follow: bool = True) -> str:
    """The token in `path` (its one line); CliError when the file is missing, not a regular
    file, readable or writable by others than its owner, owned by someone else, or the token
    is too short, too long or not one line of visible characters. `what` names the file in
    the errors; `follow`: False refuses a symbolic link (a file the tool made itself)."""
    where = f"{what} {path}"
    try:
        # The shared rule (contract/trust.py): a secret only its owner (or root) reads.
        data = read_trusted(path, Trust.SECRET, MAX_TOKEN_FILE, follow=follow)
    except UntrustedFile as exc:
        raise CliError(f"{where} {exc}") from None
    except OSError as exc:
        raise CliError(f"cannot read {where}: {exc.strerror}") from None
    return token_in(data, where)


def token_in(data: bytes, where: str) -> str:
    """The token that `data` holds as its one line; CliError naming `where` otherwise."""
    text = data.decode("ascii", "replace")
    line = text[:-2] if text.endswith("\r\n") else text[:-1] if text.endswith("\n") else text
    if len(line) > MAX_TOKEN:
        raise CliError(f"{where}: the token is longer than {MAX_TOKEN} characters")
    if not _TOKEN.fullmatch(line):
        raise CliError(
            f"{where} must hold one line, the token: visible ASCII characters, no spaces "
            "(e.g. python -c 'import secrets; print(secrets.token_urlsafe(32))')"
        )
    if len(line) < MIN_TOKEN:
        raise CliError(f"{where}: the token is shorter than {MIN_TOKEN} characters")
    return line


def own_token(path: Path, what: str) -> tuple[str, bool]:
    """The token kept in `path`, made there once (random, mode 0600) when the file does not
    exist, and True when it was made now. An existing file is read as `read_token` reads one:
    one that others may read is refused (chmod 600 it, or delete it for a new token), never
    silently replaced, as its owner may have given it a mode on purpose."""
    path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(path, flags | getattr(os, "O_CLOEXEC", 0), 0o600)
    except FileExistsError:
        return read_token(path, what, follow=False), False
    except OSError as exc:
        raise CliError(f"cannot create {what} {path}: {exc.strerror}") from None
    token = secrets.token_urlsafe(32)
    try:
        os.write(fd, f"{token}\n".encode("ascii"))  # 44 bytes: one write
    except OSError as exc:
        os.close(fd)
        with contextlib.suppress(OSError):
            path.unlink()
        raise CliError(f"cannot write {what} {path}: {exc.strerror}") from None
    os.close(fd)
    return token, True


def _digest(session_id: str) -> str:
    # Sessions are looked up by a hash of their id: the table's lookups time nothing secret.
    return hashlib.sha256(session_id.encode("ascii")).hexdigest()


@dataclass(frozen=True)
class Login:
    """How a login attempt ended: `cookie` (a Set-Cookie value) when it succeeded, else the
    reason it did not ("disabled", "wrong", "throttled")."""

    cookie: str | None
    refusal: Literal["", "disabled", "wrong", "throttled"] = ""
    retry_after: int = 0  # seconds, when throttled
    name: str = ""  # the named operator who logged in


class OperatorAuth:
    """The operators (None of either: a read-only UI): the one token of --operator-token-file
    or the named operators of --operators-file; the sessions of those who logged in, and the
    failed logins of each client (clients.py says who a client is, behind `proxies` too).
    Thread-safe."""

    def __init__(
        self,
        token: str | None,
        *,
        operators: Operators | None = None,
        proxies: Sequence[Network] = (),
        secure: bool = False,
        policy: Policy | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if token is not None and operators is not None:
            raise ValueError("one token or named operators, not both")
        # Only a hash is kept: compared in constant time, and no repr or dump shows the token.
        self._token = hashlib.sha256(token.encode("ascii")).digest() if token is not None else None
        self._operators = operators
        self.proxies = tuple(proxies)
        self.secure = secure  # cookies only over TLS
        self.policy = policy or Policy()
        self._clock = clock
        self._sessions: OrderedDict[str, _Session] = OrderedDict()
        self._failures: OrderedDict[str, deque[float]] = OrderedDict()
        # A script's Bearer credentials once verified, by their hash: scrypt once, not per call.
        self._verified: OrderedDict[bytes, str] = OrderedDict()
        self._unknown: TokenHash | None = None  # hashed against for a name nobody has
        self._lock = threading.Lock()

    @classmethod
    def from_file(
        cls,
        path: Path | None,
        *,
        operators_file: Path | None = None,
        proxies: Sequence[Network] = (),
        secure: bool = False,
    ) -> OperatorAuth:
        """The auth of `--operator-token-file` or `--operators-file` (neither: nobody is an
        operator); CliError when a file is refused (read_token, read_operators)."""
        if path is not None and operators_file is not None:
            raise CliError(
                "--operator-token-file (one operator) and --operators-file (named operators) "
                "do not go together: give one"
            )
        token = read_token(path) if path is not None else None
        operators = read_operators(operators_file) if operators_file is not None else None
        return cls(token, operators=operators, proxies=proxies, secure=secure)

    def __repr__(self) -> str:  # never the token
        return f"OperatorAuth(enabled={self.enabled}, sessions={len(self._sessions)})"

    @property
    def enabled(self) -> bool:
        """False for a read-only UI: no token, nobody logs in."""
        return self._token is not None or self._operators is not None

    @property
    def named(self) -> bool:
        """True when operators log in with their names (--operators-file)."""
        return self._operators is not None

    def client(self, peer: str, headers: Headers) -> str:
        """Whom the throttle and the audit name for a request from `peer` with `headers`."""
        return client_of(peer, headers.get_all("X-Forwarded-For") or [], self.proxies)

    def token_matches(self, given: str) -> bool:
        if self._token is None:
            return False
        try:
            candidate = given.encode("ascii")
        except UnicodeEncodeError:
            candidate = b""
        # Compared in full whatever it is, so its time says nothing of the token.
        return hmac.compare_digest(hashlib.sha256(candidate).digest(), self._token)

    def check(self, name: str, token: str) -> str | None:
        """Whose `token` is: the named operator `name` (--operators-file), "" for the single
        token, None for nobody. An unknown name costs a hash as a known one does, so the
        time of a refusal does not tell which names exist."""
        if self._operators is None:
            return "" if self.token_matches(token) else None
        known = self._operators.hashes.get(name) if name_problem(name) is None else None
        if known is None:
            if self._unknown is None:
                self._unknown = hash_token(secrets.token_urlsafe(32), COST)
            self._unknown.matches(token)
            return None
        return name if known.matches(token) else None

    # ------------------------------------------------------------------ identify

    def identify(self, headers: Headers, peer: str = "") -> Identity:
        """Who sends these headers: a Bearer header is judged alone (a script has no
        cookie); else the session cookie; else anonymous. A throttled `peer`'s named Bearer
        is refused unhashed (a guess costs the UI nothing while it waits)."""
        authorization = headers.get_all("Authorization") or []
        if authorization:
            return self._bearer(authorization, headers, peer)
        session_id = session_cookie(headers.get_all("Cookie") or [])
        if session_id is None:
            return ANONYMOUS
        return self._session(session_id)

    def _bearer(self, values: list[str], headers: Headers, peer: str) -> Identity:
        scheme, _, credentials = values[0].strip().partition(" ")
        if len(values) != 1 or scheme.lower() != "bearer" or len(credentials) > 2 * MAX_TOKEN:
            return Identity(operator=False, via="bearer")
        credentials = credentials.strip()
        if self._operators is None:
            return Identity(operator=self.token_matches(credentials), via="bearer")
        # A named operator's script sends `Bearer NAME:TOKEN` (a name has no colon).
        name, colon, token = credentials.partition(":")
        if not colon or (peer and self.blocked(self.client(peer, headers))):
            return Identity(operator=False, via="bearer")
        key = hashlib.sha256(f"{name}\0{token}".encode("utf-8", "replace")).digest()
        with self._lock:
            known = self._verified.get(key)
        if known is None:
            known = self.check(name, token)
            if known is None:
                return Identity(operator=False, via="bearer")
            with self._lock:
                self._verified[key] = known
                while len(self._verified) > MAX_VERIFIED:
                    self._verified.popitem(last=False)
        return Identity(operator=True, via="bearer", name=known)

    def _session(self, session_id: str) -> Identity:
        key = _digest(session_id)
        now = self._clock()
        with self._lock:
            session = self._sessions.get(key)
            if session is None:
                return ANONYMOUS
            if self._expired(session, now):
                del self._sessions[key]
                return ANONYMOUS
            session.used = now
            self._sessions.move_to_end(key)
            return Identity(operator=True, csrf=session.csrf, via="cookie", name=session.name)

    def _expired(self, session: _Session, now: float) -> bool:
        policy = self.policy
        return now - session.used >= policy.idle or now - session.created >= policy.lifetime

    # ------------------------------------------------------------------ login / logout

    def login(self, client: str, token: str, name: str = "") -> Login:
        """A login from `client` (as `client` groups addresses) with `token` (and, for named
        operators, `name`): a new session, or why not. While a client is throttled its
        guesses are not even compared."""
        if not self.enabled:
            return Login(None, "disabled")
        with self._lock:
            wait = self._throttled(client, self._clock())
        if wait:
            return Login(None, "throttled", wait)
        # Hashed outside the lock: a named operator's scrypt holds up no other request's look.
        who = self.check(name, token)
        now = self._clock()
        with self._lock:
            if who is None:
                self._failed(client, now)
                return Login(None, "wrong")
            self._failures.pop(client, None)
            session_id = secrets.token_urlsafe(32)
            session = _Session(secrets.token_urlsafe(32), now, now, who)
            self._sessions[_digest(session_id)] = session
            self._prune(now)
        return Login(self.cookie(session_id), name=who)

    def blocked(self, client: str) -> int:
        """Seconds `client` must wait before it may try a token again (0: it may now)."""
        with self._lock:
            return self._throttled(client, self._clock())

    def failed(self, client: str) -> None:
        """Counts a wrong token from `client` that came otherwise than by the login form (a
        bad Bearer header), so that guesses are throttled whichever way they come."""
        with self._lock:
            self._failed(client, self._clock())

    def _throttled(self, client: str, now: float) -> int:
        times = self._failures.get(client)
        if times is None:
            return 0
        while times and now - times[0] >= self.policy.window:
            times.popleft()
        if not times:
            del self._failures[client]
            return 0
        if len(times) < self.policy.guesses:
            return 0
        return max(1, int(times[0] + self.policy.window - now + 0.999))

    def _failed(self, client: str, now: float) -> None:
        times = self._failures.setdefault(client, deque(maxlen=self.policy.guesses))
        times.append(now)
        self._failures.move_to_end(client)
        while len(self._failures) > self.policy.max_clients:
            self._failures.popitem(last=False)

    def _prune(self, now: float) -> None:
        """Expired sessions go, then the least recently used beyond the table's bound."""
        for key in [k for k, s in self._sessions.items() if self._expired(s, now)]:
            del self._sessions[key]
        while len(self._sessions) > self.policy.max_sessions:
            self._sessions.popitem(last=False)

    def logout(self, headers: Headers) -> str:
        """Ends the session of these headers' cookie, if any; the Set-Cookie value that
        clears the cookie."""
        session_id = session_cookie(headers.get_all("Cookie") or [])
        if session_id is not None:
            with self._lock:
                self._sessions.pop(_digest(session_id), None)
        return self.cookie("", max_age=0)

    def cookie(self, value: str, *, max_age: int | None = None) -> str:
        """A Set-Cookie value for the session cookie: script cannot read it, no other site's
        request carries it, only TLS carries it when the UI is served over TLS."""
        age = int(self.policy.lifetime) if max_age is None else max_age
        secure = "; Secure" if self.secure else ""
        return f"{COOKIE}={value}; Path=/; Max-Age={age}; HttpOnly; SameSite=Strict{secure}"

    @property
    def sessions(self) -> int:
        return len(self._sessions)


def session_cookie(values: list[str]) -> str | None:
    """The session id in Cookie headers, when one is there and looks like one of ours."""
    found: str | None = None
    size = 0
    for value in values:
        size += len(value)
        if size > MAX_COOKIE_HEADER:
            return None
        for part in value.split(";"):
            name, eq, content = part.strip().partition("=")
            if eq and name == COOKIE:
                if found is not None:
                    return None  # two of ours: one was planted, trust neither
                found = content.strip()
    if found is None or not _SESSION_ID.fullmatch(found):
        return None
    return found


def refusal_text(login: Login, named: bool = False) -> str:
    """What the login page says of a refused login (never the token, never how close, nor
    whether a name exists)."""
    if login.refusal == "disabled":
        return "This UI has no operator token (--operator-token-file): it is read-only."
    if login.refusal == "throttled":
        return f"Too many wrong tokens from your address: try again in {login.retry_after} s."
    if named:
        return "That name and token are not an operator's."
    return "That is not the operator token."
