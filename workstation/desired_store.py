"""The desired robots of a revision, kept beside the repository's git data.

Building what a revision asks of 10,000 robots (load, validate, render) takes seconds; `status`
and the browser view ask for the same revision again and again (the reconciler's applied one).
The first reader builds it and keeps it here, `<repo>/.git/robotconf/desired/<revision>.json`;
later ones read it back in a fraction of that. A commit's content never changes, so a kept
entry is stale only when the code that built it changed: the key is the revision and a digest of
that code. What is read back is trusted only when it is the user's own regular file, bounded and
valid; anything else is ignored and built again (never an error: it is a cache).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from functools import lru_cache
from itertools import chain
from pathlib import Path
from typing import Any, TypeGuard, overload

from robotconf import configurator, contract
from robotconf.configurator.drift import Need
from robotconf.contract.wire import is_commit
from robotconf.readmodel.verdicts import DesiredRobot

FORMAT = 1
MAX_BYTES = 256 * 1024 * 1024  # far above 10,000 robots (about 4 MB): a bound, not a size
KEEP = 8  # revisions kept per repository: the newest, by when they were written
# A half-written entry (`.<revision>.<pid>.part`) older than this was left by a writer killed
# mid-write: a whole fleet's entry is written in well under a second.
STALE_PART = 300.0


@lru_cache(maxsize=1)
def code_stamp() -> str:
    """A digest of the code that turns a revision into requests (configurator and contract):
    an entry built by other code is not this code's answer."""
    digest = hashlib.sha256(f"format {FORMAT}".encode())
    for package in (configurator, contract):
        root = Path(next(iter(package.__path__)))
        for path in sorted(root.rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def encode(revision: str, robots: Mapping[str, DesiredRobot]) -> bytes:
    """The entry's bytes: column by column (checked at C speed when read back), each distinct
    need once, each robot naming its needs by their places in that table."""
    return b"".join(encoded(revision, robots))


# Robots per piece written: json.dumps makes a string per token before it joins them, and a
# whole 10,000-robot entry at once cost the reconciler 25 MB at its peak (bench/scale.py).
_SLICE = 500


def encoded(revision: str, robots: Mapping[str, DesiredRobot]) -> Iterator[bytes]:
    """`encode`'s bytes in pieces of at most _SLICE values, so that writing an entry holds
    little more than the robots themselves."""
    table: dict[Need, int] = {}
    refs = [[table.setdefault(need, len(table)) for need in r.needs] for r in robots.values()]
    listed = list(robots.values())
    head = {"stamp": code_stamp(), "revision": revision}
    yield json.dumps(head, separators=(",", ":")).encode()[:-1]
    needs: list[Sequence[Any]] = [
        [n.mapping for n in table],
        [n.name for n in table],
        [n.kind for n in table],
        [n.type for n in table],
        [list(n.logics) for n in table],
    ]
    yield b',"needs":['
    yield from _columns_encoded(needs)
    yield b'],"robots":['
    columns: list[Sequence[Any]] = [
        [r.robot_id for r in listed],
        [r.scenario for r in listed],
        [r.digest for r in listed],
        [r.suspended for r in listed],
        [r.template for r in listed],
        [r.labels for r in listed],
        [r.wave for r in listed],
        refs,
    ]
    yield from _columns_encoded(columns)
    yield b"]}"


def _columns_encoded(columns: list[Sequence[Any]]) -> Iterator[bytes]:
    """Each column as a JSON array, comma-separated, in slices of _SLICE values."""
    for number, column in enumerate(columns):
        yield b",[" if number else b"["
        for start in range(0, len(column), _SLICE):
            values = list(column[start : start + _SLICE])
            # A robot's labels may be any mapping: written as the object it is.
            part = json.dumps(values, separators=(",", ":"), default=dict)
            yield (b"," if start else b"") + part[1:-1].encode()
        yield b"]"


def decode(revision: str, data: bytes) -> dict[str, DesiredRobot] | None:
    """The robots an entry holds, or None when it is not this revision's, this code's, or not
    well formed (a reference out of range included). A robot's needs are made when first read
    (only robots that report interfaces are asked for them)."""
    try:
        found = json.loads(data)
    except (ValueError, RecursionError):
        return None
    if not isinstance(found, dict):
        return None
    if found.get("stamp") != code_stamp() or found.get("revision") != revision:
        return None
    needs, robots = found.get("needs"), found.get("robots")
    if not _columns(needs, 5) or not _columns(robots, 8):
        return None
    mappings, names, kinds, types, logics = needs
    ids, scenarios, digests, suspended, templates, labels, waves, refs = robots
    well_formed = (
        all(_only(column, str) for column in (mappings, names, kinds, types, ids, digests))
        and all(_only(column, str, NONE) for column in (scenarios, templates, waves))
        and _only(suspended, bool)
        and _only(logics, list)
        and _only(chain.from_iterable(logics), str)
        and _only(labels, dict)
        and _only(chain.from_iterable(chain.from_iterable(map(dict.items, labels))), str)
        and _only(refs, list)
        and _only(chain.from_iterable(refs), int)
        and all(0 <= i < len(mappings) for i in chain.from_iterable(refs))
    )
    if not well_formed:
        return None
    table = _NeedTable(needs)
    return {
        robot_id: DesiredRobot(
            robot_id, scenario, digest, off, template, kept, wave, KeptNeeds(table, at)
        )
        for robot_id, scenario, digest, off, template, kept, wave, at in zip(*robots, strict=True)
    }


NONE = type(None)


def _columns(found: Any, count: int) -> TypeGuard[list[list[Any]]]:
    """`count` lists of one length."""
    return (
        type(found) is list
        and len(found) == count
        and all(type(column) is list for column in found)
        and len({len(column) for column in found}) == 1
    )


def _only(values: Iterable[Any], *kinds: type) -> bool:
    """Every value is exactly of one of `kinds` (a bool is no int here; the map runs in C)."""
    return set(map(type, values)) <= set(kinds)


class _NeedTable:
    """An entry's needs, each made into a Need once, when a robot's needs are first read."""

    def __init__(self, columns: list[list[Any]]) -> None:
        self._columns = columns
        self._made: dict[int, Need] = {}

    def need(self, index: int) -> Need:
        made = self._made.get(index)
        if made is None:
            mapping, name, kind, type_, logics = (column[index] for column in self._columns)
            made = self._made[index] = Need(mapping, name, kind, type_, tuple(logics))
        return made


class KeptNeeds(Sequence[Need]):
    """A kept robot's needs, made from the entry's table when first read."""

    def __init__(self, table: _NeedTable, refs: list[int]) -> None:
        self._table = table
        self._refs = refs
        self._needs: tuple[Need, ...] | None = None

    def _made(self) -> tuple[Need, ...]:
        if self._needs is None:
            self._needs = tuple(self._table.need(i) for i in self._refs)
        return self._needs

    @overload
    def __getitem__(self, index: int) -> Need: ...

    @overload
    def __getitem__(self, index: slice) -> Sequence[Need]: ...

    def __getitem__(self, index: int | slice) -> Need | Sequence[Need]:
        return self._made()[index]

    def __len__(self) -> int:
        return len(self._refs)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and tuple(self) == tuple(other)

    def __hash__(self) -> int:
        return hash(self._made())


def _folder(repo: Path) -> Path | None:
    """Where entries of `repo` live: inside its own `.git` folder, only when that is a folder
    of the user's (a linked work tree's `.git` file, or another's repository: nothing kept)."""
    git = repo / ".git"
    try:
        found = os.lstat(git)
    except OSError:
        return None
    if not stat.S_ISDIR(found.st_mode) or found.st_uid != os.geteuid():
        return None
    return git / "robotconf" / "desired"


def read(repo: Path, revision: str) -> dict[str, DesiredRobot] | None:
    """The kept robots of `revision` (a whole commit id), or None: none kept, or not trusted."""
    folder = _folder(repo)
    if folder is None or not is_commit(revision):
        return None
    try:
        fd = os.open(folder / f"{revision}.json", os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as file:
        facts = os.fstat(file.fileno())
        trusted = (
            stat.S_ISREG(facts.st_mode)
            and facts.st_uid == os.geteuid()
            and not facts.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
            and facts.st_size <= MAX_BYTES
        )
        if not trusted:
            return None
        data = file.read(MAX_BYTES + 1)
    return decode(revision, data) if len(data) <= MAX_BYTES else None


def write(repo: Path, revision: str, robots: Mapping[str, DesiredRobot]) -> None:
    """Keeps `revision`'s robots (atomically: a reader sees a whole entry or none), and only the
    newest KEEP entries. Failing to keep is no error: the next reader builds again."""
    folder = _folder(repo)
    if folder is None or not is_commit(revision):
        return
    part = folder / f".{revision}.{os.getpid()}.part"
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
        with os.fdopen(fd, "wb") as file:
            file.writelines(encoded(revision, robots))
        os.replace(part, folder / f"{revision}.json")
        _prune(folder, time.time())
    except OSError:
        with contextlib.suppress(OSError):
            part.unlink(missing_ok=True)  # a full disk's half entry: not left behind


def _prune(folder: Path, now: float) -> None:
    """Only the newest KEEP entries, and no half-written one that a killed writer left."""
    entries = sorted(folder.glob("*.json"), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in entries[KEEP:]:
        old.unlink(missing_ok=True)
    for part in folder.glob(".*.part"):
        with contextlib.suppress(OSError):  # another writer may have just renamed it
            if now - part.lstat().st_mtime > STALE_PART:
                part.unlink()
