"""The outcome ledger: every goal outcome the robots reported, kept in SQLite under the
reconciler's state folder (`ledger.sqlite3`), and what each revision achieved read back.

The SQLite edge only: the standard library's `sqlite3`, WAL (readers never wait for the
writer), the schema versioned by `PRAGMA user_version`, each batch one transaction,
(robot_id, run, seq) unique so that a record delivered twice is kept once. What is read is
tallied by the pure functions of `readmodel/outcomes.py`.

The query API (what `robotconf history` and the browser's revision page call):

    ledger = Ledger.open(path, read_only=True)      # LedgerError: missing, corrupt, newer
    ledger.revisions()                              # [RevisionSeen], newest first
    ledger.history(rev=None, robot=None, since=None)  # History: a revision beside the one before
    ledger.report(revision, robot=None, since=None) # RevisionReport of one revision
    ledger.before(revision)                         # the revision seen before it, or None
    ledger.events(EventQuery(robot=..., kind=..., since=...))  # [KeptEvent], newest first
    find_ledger(repo, prefix, state_dir=None)       # where `history` looks for it

A kill mid-write loses nothing committed (WAL, one transaction a batch); a file that is not a
ledger (corrupt, truncated, another program's) is set aside beside it, said in one line, and a
new ledger is started: never a crash loop.

Schema 2 added the fleet's timeline (`events`: what the reconciler told or noted, see
`readmodel/timeline.py`), bounded as the outcomes are, by age and by a count of rows. A writer
opening a schema 1 ledger adds it (one transaction); a reader of one finds no events.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import sqlite3
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.readmodel.events import Event
from robotconf.readmodel.outcomes import (
    NO_REVISION,
    NO_SCENARIO,
    Group,
    History,
    RevisionReport,
    Row,
    Streak,
    StreakEvent,
    advance,
    aggregate,
)
from robotconf.readmodel.timeline import EventQuery, KeptEvent, stored

log = logging.getLogger("robotconf.reconciler")

LEDGER_FILE = "ledger.sqlite3"
SCHEMA_VERSION = 2  # 2: the events table (the timeline)
DEFAULT_MAX_AGE = 30 * 86400.0  # seconds an outcome is kept
DEFAULT_MAX_RECORDS = 5_000_000  # outcomes kept at most (about 1 GB on disk)
DEFAULT_MAX_EVENTS = 200_000  # timeline events kept at most (about 100 MB at their longest)
KEEP_ASIDE = 3  # unreadable ledgers kept beside the new one (older ones are removed)
PRUNE_CHUNK = 5000  # rows deleted per transaction when pruning: the writer is never held long
BUSY_TIMEOUT_MS = 5000
CODES_SHOWN = 10
UP_STATE = Path(".robotconf") / "up" / "state"  # `robotconf up`'s state folder in its repository

_SCHEMA = """
CREATE TABLE outcomes (
    id INTEGER PRIMARY KEY,
    robot_id TEXT NOT NULL,
    run TEXT NOT NULL,
    seq INTEGER NOT NULL,
    revision TEXT NOT NULL,
    digest TEXT,
    scenario TEXT NOT NULL,
    goal TEXT NOT NULL,
    task TEXT NOT NULL,
    outcome TEXT NOT NULL,
    code TEXT,
    message TEXT,
    started_at REAL,
    ended_at REAL NOT NULL,
    duration REAL,
    received_at REAL NOT NULL,
    UNIQUE (robot_id, run, seq)
);
CREATE INDEX outcomes_by_revision ON outcomes (revision, ended_at);
CREATE INDEX outcomes_by_robot ON outcomes (robot_id, ended_at);
CREATE INDEX outcomes_by_received ON outcomes (received_at);
CREATE TABLE revisions (
    revision TEXT PRIMARY KEY,
    first_seen REAL NOT NULL,
    last_seen REAL NOT NULL
);
CREATE INDEX revisions_by_first_seen ON revisions (first_seen);
CREATE TABLE tallies (
    revision TEXT NOT NULL,
    scenario TEXT NOT NULL,
    task TEXT NOT NULL,
    robot_id TEXT NOT NULL,
    outcome TEXT NOT NULL,
    code TEXT NOT NULL,
    count INTEGER NOT NULL,
    duration_sum REAL NOT NULL,
    durations INTEGER NOT NULL,
    PRIMARY KEY (revision, scenario, task, robot_id, outcome, code)
) WITHOUT ROWID;
CREATE TABLE streaks (
    robot_id TEXT PRIMARY KEY,
    count INTEGER NOT NULL,
    failing INTEGER NOT NULL
);
"""
# A goal's end looks up its stale record (`_supersede_stale`): only stale rows are indexed.
_STALE_INDEX = (
    "CREATE INDEX IF NOT EXISTS outcomes_stale ON outcomes (robot_id, run, goal, seq) "
    "WHERE outcome = 'stale'"
)
# Schema 2: the timeline. Ids grow with each event kept, as the outcomes' do (pruned likewise).
_EVENTS_SCHEMA = """
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY,
    at REAL NOT NULL,
    kind TEXT NOT NULL,
    message TEXT NOT NULL,
    robot_id TEXT,
    branch TEXT,
    revision TEXT,
    reason TEXT,
    refused_revision TEXT,
    by TEXT,
    subject TEXT
);
CREATE INDEX IF NOT EXISTS events_by_at ON events (at);
CREATE INDEX IF NOT EXISTS events_by_robot ON events (robot_id, at);
CREATE INDEX IF NOT EXISTS events_by_kind ON events (kind, at);
"""
_TABLES = {"outcomes", "revisions", "tallies", "streaks"}
_EVENT_COLUMNS = (
    "at, kind, message, robot_id, branch, revision, reason, refused_revision, by, subject"
)
# The outcomes' counts kept beside them, per (revision, scenario, task, robot, outcome, code),
# updated in each batch's transaction: a report of a revision reads its tallies, not its rows
# (a million rows take seconds to group; their tallies, milliseconds).
_TALLY = (
    "INSERT INTO tallies (revision, scenario, task, robot_id, outcome, code, count, "
    "duration_sum, durations) VALUES (?,?,?,?,?,?,?,?,?) ON CONFLICT DO UPDATE SET "
    "count = count + excluded.count, duration_sum = duration_sum + excluded.duration_sum, "
    "durations = durations + excluded.durations"
)
_TALLY_KEY = "revision, scenario, task, robot_id, outcome, coalesce(code, '')"


class LedgerError(Exception):
    """The ledger cannot be used as asked, in one line (never a traceback). `unreadable`: the
    file is not a ledger or is corrupt (a writer sets it aside), rather than out of reach
    (permissions) or of a newer schema (kept as it is)."""

    def __init__(self, message: str, *, unreadable: bool = False) -> None:
        super().__init__(message)
        self.unreadable = unreadable


@dataclass(frozen=True)
class RevisionSeen:
    """A revision the ledger holds outcomes of: when the first and last arrived (unix time,
    the reconciler's clock)."""

    revision: str
    first_seen: float
    last_seen: float


@dataclass(frozen=True)
class Added:
    """What one batch did: records kept, those already kept (a redelivery), and the robots'
    failing or recovered transitions it made."""

    kept: list[OutcomeRecord]
    duplicates: int
    events: list[StreakEvent]


def default_state_dir(prefix: str) -> Path:
    """The reconciler's state folder for a topic prefix, outside any repository:
    `$XDG_STATE_HOME/robotconf/reconciler/<prefix>` (by default under ~/.local/state)."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    slug = re.sub(r"[^A-Za-z0-9_.-]", "_", prefix).strip(".") or "fleet"
    return Path(base) / "robotconf" / "reconciler" / slug


def ledger_path(state_dir: Path) -> Path:
    return state_dir / LEDGER_FILE


def find_ledger(repo: Path, prefix: str, state_dir: Path | None = None) -> Path:
    """Where `history` (and the browser) read the ledger: in `state_dir` when given; else
    `robotconf up`'s, when the repository has one; else the reconciler's default for the
    prefix."""
    if state_dir is not None:
        return ledger_path(state_dir)
    up = ledger_path(repo.absolute() / UP_STATE)
    if up.exists():
        return up
    return ledger_path(default_state_dir(prefix))


class _LedgerReads:
    """What a ledger answers: the queries of `history`, the browser and a rollout's evidence,
    each on the one connection its `Ledger` holds."""

    _db: sqlite3.Connection
    path: Path

    # ------------------------------------------------------------------ reading

    def count(self) -> int:
        """Outcomes kept (a full count: for tests and benchmarks)."""
        return int(self._db.execute("SELECT count(*) FROM outcomes").fetchone()[0])

    def revisions(self) -> list[RevisionSeen]:
        """Every revision the ledger holds outcomes of, newest (first seen last) first."""
        return [
            RevisionSeen(revision, first, last)
            for revision, first, last in self._read(
                "SELECT revision, first_seen, last_seen FROM revisions "
                "ORDER BY first_seen DESC, revision"
            )
        ]

    def resolve(self, rev: str) -> RevisionSeen:
        """The revision `rev` names: whole, or the start of one (at least 4 characters)."""
        if len(rev) < 4 and rev != NO_REVISION:
            raise LedgerError(f"--rev {rev!r}: give at least 4 characters of a revision")
        found = [seen for seen in self.revisions() if seen.revision.startswith(rev)]
        exact = [seen for seen in found if seen.revision == rev]
        if exact:
            return exact[0]
        if not found:
            raise LedgerError(f"the ledger holds no outcomes of a revision {rev!r}")
        if len(found) > 1:
            names = ", ".join(seen.revision[:12] for seen in found[:5])
            raise LedgerError(f"--rev {rev!r} names several revisions: {names}")
        return found[0]

    def before(self, revision: str) -> str | None:
        """The revision whose outcomes began arriving last before `revision`'s did."""
        row = self._read(
            "SELECT r.revision FROM revisions r, revisions this WHERE this.revision = ? "
            "AND (r.first_seen < this.first_seen OR (r.first_seen = this.first_seen AND "
            "r.revision < this.revision)) ORDER BY r.first_seen DESC, r.revision DESC LIMIT 1",
            (revision,),
        )
        return row[0][0] if row else None

    def evidence_rows(
        self, *, after: int = 0, since: float | None = None, limit: int = 50_000
    ) -> list[Row]:
        """Outcomes in the order the ledger kept them, for a wave's evidence: those after the
        row `after`, or (a first count) those received at or after `since`; at most `limit`."""
        if since is not None and after == 0:
            where, args = "received_at >= ?", (since, limit)
        else:
            where, args = "id > ?", (after, limit)
        return [
            Row(*row)
            for row in self._read(
                "SELECT id, robot_id, digest, scenario, outcome, code, received_at FROM outcomes "
                f"WHERE {where} ORDER BY id LIMIT ?",
                list(args),
            )
        ]

    def report(
        self, revision: str, *, robot: str | None = None, since: float | None = None
    ) -> RevisionReport:
        """What `revision` achieved: its outcomes (of `robot`, ended at or after `since`)
        tallied per scenario, task and robot."""
        where, args = "revision = ?", list[object]([revision])
        if robot is not None:
            where += " AND robot_id = ?"
            args.append(robot)
        if since is None:  # the tallies hold it all
            table, count, total, timed = (
                "tallies",
                "sum(count)",
                "sum(duration_sum)",
                "sum(durations)",
            )
            codes_where = f"{where} AND code != ''"
        else:
            where += " AND ended_at >= ?"
            args.append(since)
            table, count, total, timed = (
                "outcomes",
                "count(*)",
                "total(duration)",
                "count(duration)",
            )
            codes_where = f"{where} AND code IS NOT NULL"
        tasks = [
            Group(revision, OutcomeState(outcome), n, dsum, dn, scenario=scenario, task=task)
            for scenario, task, outcome, n, dsum, dn in self._read(
                f"SELECT scenario, task, outcome, {count}, {total}, {timed} FROM {table} "
                f"WHERE {where} GROUP BY scenario, task, outcome",
                args,
            )
            if outcome in _STATES
        ]
        robots = [
            Group(revision, OutcomeState(outcome), n, dsum, dn, robot_id=robot_id)
            for robot_id, outcome, n, dsum, dn in self._read(
                f"SELECT robot_id, outcome, {count}, {total}, {timed} FROM {table} "
                f"WHERE {where} GROUP BY robot_id, outcome",
                args,
            )
            if outcome in _STATES
        ]
        codes = dict(
            self._read(
                f"SELECT code, {count} FROM {table} WHERE {codes_where} GROUP BY code "
                f"ORDER BY {count} DESC, code LIMIT {CODES_SHOWN}",
                args,
            )
        )
        seen = self._read(
            "SELECT first_seen, last_seen FROM revisions WHERE revision = ?", (revision,)
        )
        first, last = seen[0] if seen else (None, None)
        return aggregate(revision, tasks, robots, codes, first_seen=first, last_seen=last)

    def history(
        self, rev: str | None = None, *, robot: str | None = None, since: float | None = None
    ) -> History:
        """What a revision achieved beside the revision before it: `rev` (whole or its start),
        by default the newest seen. LedgerError when the ledger holds none."""
        if rev is None:
            newest = self.revisions()
            if not newest:
                raise LedgerError(f"the ledger {self.path} holds no goal outcomes yet")
            revision = newest[0].revision
        else:
            revision = self.resolve(rev).revision
        previous = self.before(revision)
        return History(
            report=self.report(revision, robot=robot, since=since),
            before=(None if previous is None else self.report(previous, robot=robot, since=since)),
            robot=robot,
            since=since,
        )

    def events(self, query: EventQuery | None = None) -> list[KeptEvent]:
        """The kept events `query` asks for, newest first (a ledger of schema 1: none)."""
        query = query if query is not None else EventQuery()
        if not self._read("SELECT 1 FROM sqlite_master WHERE type='table' AND name='events'"):
            return []
        where, args = [], list[object]()
        if query.robot is not None:
            where.append("robot_id = ?")
            args.append(query.robot)
        if query.kind is not None:
            where.append("kind = ?")
            args.append(query.kind)
        if query.since is not None:
            where.append("at >= ?")
            args.append(query.since)
        sql = f"SELECT {_EVENT_COLUMNS} FROM events"
        if where:
            sql += " WHERE " + " AND ".join(where)
        args.append(query.limit)
        return [
            KeptEvent(*row) for row in self._read(f"{sql} ORDER BY at DESC, id DESC LIMIT ?", args)
        ]

    def _read(self, sql: str, args: Sequence[object] = ()) -> list[Any]:
        """A query's rows; LedgerError when the file turns out unreadable."""
        try:
            return self._db.execute(sql, args).fetchall()
        except sqlite3.DatabaseError as exc:
            raise LedgerError(f"cannot read the ledger {self.path}: {exc}") from None


class Ledger(_LedgerReads):
    """One connection to one ledger file. A writer (the reconciler's feed) adds and prunes
    from one thread; readers open their own, read-only."""

    def __init__(self, connection: sqlite3.Connection, path: Path, read_only: bool) -> None:
        self._db = connection
        self.path = path
        self.read_only = read_only

    # ------------------------------------------------------------------ opening

    @classmethod
    def open(cls, path: Path, *, read_only: bool = False, check: bool = True) -> Ledger:
        """An existing ledger, or (for a writer) a new one where none is. LedgerError when it
        is missing (read-only), not a ledger, corrupt, or of a newer schema; `check` runs
        SQLite's quick_check first (a full read of the file)."""
        if read_only and not path.is_file():
            raise LedgerError(
                f"no ledger at {path}: the reconciler writes it in its --state-dir once robots "
                "report goal outcomes (robotconf history --state-dir DIR reads another)"
            )
        try:
            connection = _connect(path, read_only)
        except sqlite3.DatabaseError as exc:
            raise _refusal(path, exc) from None
        ledger = cls(connection, path, read_only)
        try:
            ledger._prepare(check)
        except LedgerError:
            connection.close()
            raise
        except sqlite3.DatabaseError as exc:
            connection.close()
            raise _refusal(path, exc) from None
        return ledger

    @classmethod
    def open_or_start(
        cls, path: Path, say: Callable[[str], None] | None = None, *, check: bool = True
    ) -> Ledger:
        """The writer's ledger: the one at `path`, or a new one. A file there that is not a
        ledger, or a corrupt one, is moved aside (its name gains `.unreadable-<time>`) and said
        in one line through `say`; a new ledger starts. LedgerError only when no ledger can be
        made there at all (the folder cannot be written, a newer schema)."""
        tell = say or log.error
        try:
            # The reconciler's alone: outcome messages are the robots' words, for its operators.
            path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError as exc:
            raise LedgerError(
                f"cannot make the state folder {path.parent}: {exc.strerror or exc}"
            ) from None
        existed = path.exists()
        try:
            return cls.open(path, check=check)
        except LedgerError as exc:
            if not exc.unreadable or not existed:
                raise
            aside = set_aside(path)
            tell(f"{exc}; kept aside as {aside.name}, starting a new ledger")
        return cls.open(path, check=False)

    def _prepare(self, check: bool) -> None:
        db = self._db
        version = db.execute("PRAGMA user_version").fetchone()[0]
        tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if version > SCHEMA_VERSION:
            raise LedgerError(
                f"{self.path} is a ledger of a newer robotconf (schema {version}, this one knows "
                f"up to {SCHEMA_VERSION}): upgrade robotconf, or give another --state-dir"
            )
        if version == 0:
            if tables:
                raise LedgerError(
                    f"{self.path} is an SQLite database but not a ledger", unreadable=True
                )
            if self.read_only:
                raise LedgerError(f"{self.path} is an empty ledger")
            db.execute("PRAGMA journal_mode=WAL")
            with self._transaction():
                for statement in (_SCHEMA + _EVENTS_SCHEMA).split(";"):
                    if statement.strip():
                        db.execute(statement)
                db.execute(_STALE_INDEX)
                db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            return
        if not tables >= _TABLES:
            missing = sorted(_TABLES - tables)
            raise LedgerError(f"{self.path} lacks tables of a ledger: {missing}", unreadable=True)
        if check:
            found = [row[0] for row in db.execute("PRAGMA quick_check(3)")]
            if found != ["ok"]:
                raise LedgerError(f"{self.path} is corrupt: {'; '.join(found)}", unreadable=True)
        if not self.read_only:
            db.execute("PRAGMA journal_mode=WAL")
            # Ledgers made before rollouts counted evidence lack it (made once, at open).
            db.execute("CREATE INDEX IF NOT EXISTS outcomes_by_received ON outcomes (received_at)")
            # Ledgers made before it: without it each goal's end scanned all of its run's
            # records for a stale one (a long run made adding quadratic).
            db.execute(_STALE_INDEX)
            if version < SCHEMA_VERSION:
                self._migrate(version)

    def _migrate(self, version: int) -> None:
        """A ledger of an older schema brought up to this one, in one transaction."""
        with self._transaction():
            if version < 2:
                for statement in _EVENTS_SCHEMA.split(";"):
                    if statement.strip():
                        self._db.execute(statement)
            self._db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
        log.info("ledger: %s brought from schema %d to %d", self.path, version, SCHEMA_VERSION)

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> Ledger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[None]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            with contextlib.suppress(sqlite3.Error):
                self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    # ------------------------------------------------------------------ writing

    def add(
        self,
        records: Sequence[OutcomeRecord],
        received_at: float | None = None,
        streak: int | None = None,
    ) -> Added:
        """Keeps `records` in one transaction (committed when this returns: a kill after it
        loses none of them). A record already kept is skipped. With `streak`, the robots'
        failing streaks advance by the records kept, in the same transaction."""
        now = time.time() if received_at is None else received_at
        db = self._db
        kept: list[OutcomeRecord] = []
        with self._transaction():
            revisions: dict[str, None] = {}
            for record in records:
                revision = record.revision or NO_REVISION
                cursor = db.execute(
                    "INSERT OR IGNORE INTO outcomes (robot_id, run, seq, revision, digest, "
                    "scenario, goal, task, outcome, code, message, started_at, ended_at, "
                    "duration, received_at) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    (
                        record.robot_id,
                        record.run,
                        record.seq,
                        revision,
                        record.digest,
                        record.scenario or NO_SCENARIO,
                        record.goal,
                        record.task,
                        record.outcome.value,
                        record.code,
                        record.message,
                        record.started_at,
                        min(record.ended_at, now),  # a robot's clock ahead is not the future
                        record.duration,
                        now,
                    ),
                )
                if cursor.rowcount == 1:
                    kept.append(record)
                    revisions[revision] = None
            duplicates = len(records) - len(kept)
            kept = self._supersede_stale(kept)
            db.executemany(_TALLY, _tallies(kept))
            db.executemany(
                "INSERT INTO revisions (revision, first_seen, last_seen) VALUES (?, ?, ?) "
                "ON CONFLICT (revision) DO UPDATE SET last_seen = excluded.last_seen",
                [(revision, now, now) for revision in revisions],
            )
            events = self._advance_streaks(kept, streak) if streak is not None else []
        return Added(kept, duplicates, events)

    def _supersede_stale(self, kept: list[OutcomeRecord]) -> list[OutcomeRecord]:
        """A goal the agent called stale that ended after all (its end comes later in the same
        run, with a higher seq) is counted by its end alone: its stale record goes, from the
        tallies too. Returns `kept` less the stale records of this batch that went."""
        db = self._db
        batch = {(r.robot_id, r.run, r.seq) for r in kept}
        gone: set[tuple[str, str, int]] = set()
        for record in kept:
            if record.outcome is OutcomeState.STALE:
                continue
            rows = db.execute(
                f"SELECT id, seq, {_TALLY_KEY}, duration FROM outcomes WHERE robot_id = ? "
                "AND run = ? AND goal = ? AND outcome = 'stale' AND seq < ?",
                (record.robot_id, record.run, record.goal, record.seq),
            ).fetchall()
            for row_id, seq, *key, duration in rows:
                db.execute("DELETE FROM outcomes WHERE id = ?", (row_id,))
                found = (record.robot_id, record.run, seq)
                gone.add(found)
                if found in batch:
                    continue  # of this batch: not tallied yet
                db.execute(
                    "UPDATE tallies SET count = count - 1, duration_sum = duration_sum - ?, "
                    "durations = durations - ? WHERE revision = ? AND scenario = ? AND "
                    "task = ? AND robot_id = ? AND outcome = ? AND code = ?",
                    (duration or 0.0, int(duration is not None), *key),
                )
        if not gone:
            return kept
        db.execute("DELETE FROM tallies WHERE count <= 0")
        return [r for r in kept if (r.robot_id, r.run, r.seq) not in gone]

    def _advance_streaks(self, kept: list[OutcomeRecord], threshold: int) -> list[StreakEvent]:
        robots = sorted({record.robot_id for record in kept})
        known = self.streaks(robots)
        changed, events = advance(known, kept, threshold)
        self._db.executemany(
            "INSERT OR REPLACE INTO streaks (robot_id, count, failing) VALUES (?, ?, ?)",
            [
                (robot, streak.count, int(streak.failing))
                for robot, streak in changed.items()
                if streak != known.get(robot, Streak())
            ],
        )
        return events

    def add_events(self, events: Sequence[Event]) -> int:
        """Keeps `events` (each field bounded: `timeline.stored`) in one transaction; how many."""
        rows = [
            (
                kept.at,
                kept.kind,
                kept.message,
                kept.robot,
                kept.branch,
                kept.revision,
                kept.reason,
                kept.refused_revision,
                kept.by,
                kept.subject,
            )
            for kept in map(stored, events)
        ]
        with self._transaction():
            self._db.executemany(
                f"INSERT INTO events ({_EVENT_COLUMNS}) VALUES (?,?,?,?,?,?,?,?,?,?)", rows
            )
        return len(rows)

    def streaks(self, robots: Sequence[str]) -> dict[str, Streak]:
        """The failing streaks of `robots` (those with none are not in the result)."""
        found: dict[str, Streak] = {}
        for start in range(0, len(robots), 500):
            chunk = robots[start : start + 500]
            marks = ",".join("?" * len(chunk))
            for robot, count, failing in self._db.execute(
                f"SELECT robot_id, count, failing FROM streaks WHERE robot_id IN ({marks})",
                chunk,
            ):
                found[robot] = Streak(count, bool(failing))
        return found

    def prune(
        self,
        max_age: float = DEFAULT_MAX_AGE,
        max_records: int = DEFAULT_MAX_RECORDS,
        now: float | None = None,
        chunks: int | None = None,
    ) -> int:
        """Removes the oldest outcomes beyond `max_records` and those received more than
        `max_age` seconds ago, a chunk per transaction (at most `chunks` of them); how many
        went. Revisions left without outcomes go too. The file keeps its size and reuses the
        free pages."""
        now = time.time() if now is None else now
        removed = 0
        while chunks is None or removed < chunks * PRUNE_CHUNK:
            low, high = self._db.execute("SELECT min(id), max(id) FROM outcomes").fetchone()
            if low is None:
                break
            # Ids grow by one per kept record and only the oldest are removed: the count is
            # high - low + 1, without counting the rows.
            over = (high - low + 1) - max_records
            old = self._db.execute(
                "SELECT id FROM outcomes WHERE id < ? AND received_at < ? ORDER BY id DESC LIMIT 1",
                (low + PRUNE_CHUNK, now - max_age),
            ).fetchone()
            cutoff = low - 1 + min(PRUNE_CHUNK, max(over, 0))
            if old is not None:
                cutoff = max(cutoff, old[0])
            if cutoff < low:
                break
            with self._transaction():
                self._untally(cutoff)
                removed += self._db.execute(
                    "DELETE FROM outcomes WHERE id <= ?", (cutoff,)
                ).rowcount
        if removed:
            with self._transaction():
                self._db.execute(
                    "DELETE FROM revisions WHERE NOT EXISTS (SELECT 1 FROM outcomes "
                    "WHERE outcomes.revision = revisions.revision)"
                )
        return removed

    def prune_events(
        self,
        max_age: float = DEFAULT_MAX_AGE,
        max_events: int = DEFAULT_MAX_EVENTS,
        now: float | None = None,
    ) -> int:
        """Removes the oldest events beyond `max_events` and those older than `max_age`
        seconds, at most PRUNE_CHUNK of them (one transaction); how many went (PRUNE_CHUNK:
        more may be left). As `prune` does the outcomes, by id: the oldest have the lowest."""
        now = time.time() if now is None else now
        low, high = self._db.execute("SELECT min(id), max(id) FROM events").fetchone()
        if low is None:
            return 0
        over = (high - low + 1) - max_events
        cutoff = low - 1 + min(PRUNE_CHUNK, max(over, 0))
        old = self._db.execute(
            "SELECT id FROM events WHERE id < ? AND at < ? ORDER BY id DESC LIMIT 1",
            (low + PRUNE_CHUNK, now - max_age),
        ).fetchone()
        if old is not None:
            cutoff = max(cutoff, old[0])
        if cutoff < low:
            return 0
        with self._transaction():
            return int(self._db.execute("DELETE FROM events WHERE id <= ?", (cutoff,)).rowcount)

    def _untally(self, cutoff: int) -> None:
        """The tallies without the outcomes up to `cutoff`, about to be removed."""
        db = self._db
        db.executemany(
            "UPDATE tallies SET count = count - ?, duration_sum = duration_sum - ?, "
            "durations = durations - ? WHERE revision = ? AND scenario = ? AND task = ? "
            "AND robot_id = ? AND outcome = ? AND code = ?",
            [
                (n, total, timed, *key)
                for *key, n, total, timed in db.execute(
                    f"SELECT {_TALLY_KEY}, count(*), total(duration), count(duration) "
                    f"FROM outcomes WHERE id <= ? GROUP BY {_TALLY_KEY}",
                    (cutoff,),
                )
            ],
        )
        db.execute("DELETE FROM tallies WHERE count <= 0")

    def checkpoint(self) -> None:
        """Folds the write-ahead log into the file (SQLite also does it every 1,000 pages)."""
        self._db.execute("PRAGMA wal_checkpoint(PASSIVE)")


_STATES = {state.value for state in OutcomeState}


def _tallies(kept: Sequence[OutcomeRecord]) -> list[tuple[object, ...]]:
    """The kept records' counts per tally key (`_TALLY`'s parameters)."""
    found: dict[tuple[str, ...], list[float]] = {}
    for record in kept:
        key = (
            record.revision or NO_REVISION,
            record.scenario or NO_SCENARIO,
            record.task,
            record.robot_id,
            record.outcome.value,
            record.code or "",
        )
        sums = found.setdefault(key, [0, 0.0, 0])
        sums[0] += 1
        if record.duration is not None:
            sums[1] += record.duration
            sums[2] += 1
    return [(*key, int(n), total, int(timed)) for key, (n, total, timed) in found.items()]


def _refusal(path: Path, exc: sqlite3.DatabaseError) -> LedgerError:
    """SQLite's error opening `path`, in one line: out of reach (an OperationalError: no
    permission, a folder), or not a readable ledger (anything else: not a database, corrupt)."""
    if isinstance(exc, sqlite3.OperationalError) and "malformed" not in str(exc):
        return LedgerError(f"cannot open the ledger {path}: {exc}")
    return LedgerError(f"{path} is not a readable ledger: {exc}", unreadable=True)


def _connect(path: Path, read_only: bool) -> sqlite3.Connection:
    if read_only:
        uri = f"{path.absolute().as_uri()}?mode=ro"
        connection = sqlite3.connect(uri, uri=True, isolation_level=None, check_same_thread=False)
    else:
        connection = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
    connection.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
    if not read_only:
        # A commit is in the write-ahead log when it returns: a killed process loses none.
        # (NORMAL, not FULL: an operating system crash may lose the last commits, which the
        # broker no longer holds; a process kill, the common case, loses nothing.)
        connection.execute("PRAGMA synchronous=NORMAL")
    return connection


def set_aside(path: Path, now: float | None = None) -> Path:
    """Moves an unreadable ledger (and its -wal and -shm) aside, keeping the newest
    KEEP_ASIDE such sets; the new name of the main file."""
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime(time.time() if now is None else now))
    aside = path.with_name(f"{path.name}.unreadable-{stamp}")
    n = 1
    while aside.exists():
        n += 1
        aside = path.with_name(f"{path.name}.unreadable-{stamp}-{n}")
    for suffix in ("-wal", "-shm"):
        side = path.with_name(path.name + suffix)
        if side.exists():
            os.replace(side, aside.with_name(aside.name + suffix))
    os.replace(path, aside)
    kept = sorted(  # by name: the time is in it
        p
        for p in path.parent.glob(f"{path.name}.unreadable-*")
        if not p.name.endswith(("-wal", "-shm"))
    )
    for old in kept[:-KEEP_ASIDE]:
        for side in (old, old.with_name(old.name + "-wal"), old.with_name(old.name + "-shm")):
            side.unlink(missing_ok=True)
    return aside
