"""Files trusted as configuration or credentials are checked before they are read, the way
ssh checks a key file and git a repository: owned by the user running the command (or root),
never changed by others, a secret never read by others, a link refused where the tool names
the path itself, bounded before reading
(docs/how-to/production-broker.md#files-checked-before-trusted).

`refusal` is the rule, pure over a file's facts; `read_trusted` and `check_trusted` are its
edge (one open, one fstat: what is judged is what is read). Stdlib only: the agent uses it too.
"""

from __future__ import annotations

import errno
import os
import stat
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from robotconf.contract.files import NotRegularFile, file_kind

ROOT = 0


class Trust(Enum):
    """What a file is to the tool: configuration (others may read it, never change it) or a
    secret (others may neither read nor change it, as ssh asks of a private key)."""

    CONFIG = "config"
    SECRET = "secret"


@dataclass(frozen=True)
class FileFacts:
    """What the kernel says of a file (its lstat or fstat), all the rule looks at."""

    uid: int
    mode: int  # st_mode: kind and permission bits
    size: int


class UntrustedFile(NotRegularFile):
    """A file refused before it is read: its message says why and what would be right (the
    same as `strerror`, which callers that report an OSError show)."""

    def __init__(self, reason: str, path: Path | str | None = None) -> None:
        super().__init__(errno.EACCES, reason, None if path is None else str(path))

    def __str__(self) -> str:
        return self.strerror or ""


def euid() -> int:
    return os.geteuid() if hasattr(os, "geteuid") else ROOT


def owner_trusted(uid: int, me: int) -> bool:
    """A file or folder is trusted when the user running the command or root owns it: root
    can change anything anyway, anyone else could have planted it (git's safe.directory)."""
    return uid in (me, ROOT)


def refusal(facts: FileFacts, me: int, kind: Trust, path: str, limit: int) -> str | None:
    """Why `path` must not be trusted, as a reason and a fix ("is ...: chmod 600 PATH"); None
    when it may be read."""
    mode = facts.mode
    if not stat.S_ISREG(mode):
        what = file_kind(mode) or "a folder"
        return f"is {what}, not a regular file: put the file itself at {path}"
    if not owner_trusted(facts.uid, me):
        return (
            f"belongs to user id {facts.uid}, not to you (uid {me}) or root: anyone may have "
            f"put it there; use a file of your own (cp it, then chown {me} {path})"
        )
    bits = stat.S_IMODE(mode)
    if bits & 0o022:
        fix = "chmod 600" if kind is Trust.SECRET else "chmod go-w"
        return f"may be changed by others (mode {bits:04o}): {fix} {path}"
    if kind is Trust.SECRET and bits & 0o044:
        return f"may be read by others (mode {bits:04o}): chmod 600 {path}, as ssh asks of a key"
    if facts.size > limit:
        return f"is {facts.size:,} bytes, over the limit of {limit:,}"
    return None


def folder_refusal(uid: int, me: int, path: str) -> str | None:
    """Why a folder is not walked into when looking for a file upward (None: it may be)."""
    if owner_trusted(uid, me):
        return None
    return (
        f"{path} belongs to user id {uid}, not to you (uid {me}) or root: not looked at "
        "(as git's safe.directory); run the command from a folder of your own"
    )


def facts_of(info: os.stat_result) -> FileFacts:
    return FileFacts(uid=info.st_uid, mode=info.st_mode, size=info.st_size)


def _open(path: Path, follow: bool) -> int:
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if not follow:
        flags |= getattr(os, "O_NOFOLLOW", 0)
    try:
        return os.open(path, flags)
    except OSError as exc:
        if exc.errno == errno.ELOOP and not follow:
            raise UntrustedFile(
                f"is a symbolic link, not a regular file: put the file itself at {path}", path
            ) from None
        raise


def open_trusted(path: Path, kind: Trust, limit: int, *, follow: bool = True) -> int:
    """An open descriptor of `path` once it passed the rule, judged on the open file itself
    (fstat): a file swapped in after a look is never the one read. The caller closes it.
    `follow=False` refuses a symbolic link (a path the tool names itself: a link there was put
    by someone else); a path the user gives may be a link, and its target is judged."""
    fd = _open(path, follow)
    try:
        reason = refusal(facts_of(os.fstat(fd)), euid(), kind, str(path), limit)
    except BaseException:
        os.close(fd)
        raise
    if reason is not None:
        os.close(fd)
        raise UntrustedFile(reason, path)
    return fd


def read_trusted(path: Path, kind: Trust, limit: int, *, follow: bool = True) -> bytes:
    """The bytes of `path` when it passes the rule; UntrustedFile (an OSError) saying why not,
    other OSErrors when it cannot be opened."""
    fd = open_trusted(path, kind, limit, follow=follow)
    try:
        with os.fdopen(fd, "rb", closefd=False) as stream:
            data = stream.read(limit + 1)
    finally:
        os.close(fd)
    if len(data) > limit:
        raise UntrustedFile(f"is over the limit of {limit:,} bytes", path)
    return data


def check_trusted(path: Path, kind: Trust, limit: int, *, follow: bool = True) -> None:
    """Judges a file that another library reads by its path (TLS keys and certificates)."""
    os.close(open_trusted(path, kind, limit, follow=follow))


def read_secret_text(path: Path, limit: int = 64 * 1024) -> str:
    """A secret file's text without surrounding white space (a password file's one line)."""
    return read_trusted(path, Trust.SECRET, limit).decode("utf-8").strip()
