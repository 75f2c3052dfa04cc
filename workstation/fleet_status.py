"""The fleet as `status` sees it: a broker client reading the retained topics, compared with the
repository, as one FleetStatus now or one per change (`--watch`)."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

from robotconf.configurator.drift import DriftMemo
from robotconf.configurator.gcpause import collector_paused
from robotconf.configurator.render import RenderError, render_fleet
from robotconf.configurator.source import SourceError
from robotconf.configurator.workspace import check
from robotconf.contract.mqtt import Connection
from robotconf.contract.topics import Role, subscriptions
from robotconf.contract.wire import ReconcilerStatus, Topics
from robotconf.readmodel.observed import ReadMemo, parse_retained
from robotconf.readmodel.retained import RetainedView
from robotconf.readmodel.verdicts import (
    DesiredRobot,
    FleetStatus,
    Verdict,
    build_rows,
    desired_from_fleet,
    desired_from_retained,
    short_rev,
)
from robotconf.workstation import desired_store

CONFIRM_TIMEOUT = 5.0  # seconds for the few topics a lossy-looking read is checked with

Desired = tuple[dict[str, DesiredRobot] | None, str, list[str]]


class DesiredSource(Protocol):
    """Where a reader gets the desired robots to compare with, given the reconciler's status."""

    def get(self, reconciler: ReconcilerStatus | None) -> Desired: ...


@dataclass(frozen=True)
class Given:
    """A desired state already made."""

    value: Desired

    def get(self, reconciler: ReconcilerStatus | None) -> Desired:
        return self.value


class DesiredCache:
    """The desired robots for `status`, re-read only when the revision to compare with moves."""

    def __init__(self, repo: Path, rev: str | None) -> None:
        self.repo = repo
        self.rev = rev
        self._key: tuple[str | None, str | None] | None = None
        self._value: Desired = ({}, "", [])

    def get(self, reconciler: ReconcilerStatus | None) -> Desired:
        applied = reconciler.last_applied_revision if reconciler else None
        key = (self.rev, applied)
        if key != self._key:
            with collector_paused():  # 10,000 robots' objects, all alive afterwards
                self._value = self._load(applied)
            self._key = key
        return self._value

    def _load(self, applied: str | None) -> Desired:
        notes: list[str] = []
        # What the reconciler applied is what robots should run; the work tree is the fallback.
        candidates: list[str | None] = (
            [self.rev] if self.rev else [applied, None] if applied else [None]
        )
        for rev in candidates:
            kept = desired_store.read(self.repo, rev) if rev else None
            if kept is not None and rev is not None:
                return kept, f"{self.repo} at {short_rev(rev)}", notes
            try:
                checked = check(self.repo, rev)
            except SourceError as exc:
                notes.append(f"{exc}")
                continue
            where = f"{self.repo} at {short_rev(checked.repo.revision)}"
            if not checked.ok:
                notes.append(f"{where} has {len(checked.errors)} error(s) (robotconf validate)")
                continue
            try:
                fleet = render_fleet(checked.repo)
            except RenderError as exc:
                notes.append(f"{where}: {exc}")
                continue
            robots = desired_from_fleet(fleet)
            if rev is not None and checked.repo.revision == rev:
                desired_store.write(self.repo, rev, robots)
            return robots, where, notes
        return None, "the retained launch topics (no valid repository to compare with)", notes


def fleet_status(
    messages: dict[str, bytes],
    topics: Topics,
    desired: DesiredSource,
    memos: dict[bool, ReadMemo] | None = None,
    drift: DriftMemo | None = None,
    lost: str | None = None,
) -> FleetStatus:
    """`memos` (one per way of reading requests, in full or not): what was read of each
    payload, kept for the next call (`--watch` reads only what changed); `drift`: each robot's
    drift, worked out again only for a robot whose request or interfaces changed."""
    # Reading 10,000 robots makes objects that all live on: a collection of the young ones
    # would walk them again and again (most of the time spent on the desired robots' needs).
    with collector_paused():
        fleet = _fleet_status(messages, topics, desired, memos, drift)
    return fleet if lost is None else unknown_when_lost(fleet, messages, topics, lost)


def _fleet_status(
    messages: dict[str, bytes],
    topics: Topics,
    desired: DesiredSource,
    memos: dict[bool, ReadMemo] | None,
    drift: DriftMemo | None,
) -> FleetStatus:
    # With a repository to compare with, the requests' digests are all a row needs: 10,000
    # requests are validated in full only when they are the one account of what is desired.
    status = {t: m for t, m in messages.items() if t == topics.reconciler_status}
    robots, where, notes = desired.get(parse_retained(status, topics).reconciler)
    full = robots is None
    memo = memos.setdefault(full, ReadMemo()) if memos is not None else None
    retained = parse_retained(messages, topics, requests=full, memo=memo)
    if robots is None:
        robots = desired_from_retained(retained)
    rows = build_rows(robots, retained, drift)
    return FleetStatus(rows, retained.reconciler, where, list(notes), retained.ignored)


def unknown_when_lost(
    fleet: FleetStatus, messages: dict[str, bytes], topics: Topics, lost: str
) -> FleetStatus:
    """A read the broker cut short (`lost`, why) calls no robot Offline for want of a status:
    such a robot is Unknown, and the report says how many and what to do."""
    rows = [
        replace(
            row,
            verdict=Verdict.UNKNOWN,
            reason="the broker dropped its retained status on the way here",
            state="unknown",
        )
        if row.verdict is Verdict.OFFLINE and topics.status(row.robot_id) not in messages
        else row
        for row in fleet.rows
    ]
    unknown = sum(row.verdict is Verdict.UNKNOWN for row in rows)
    reconciler = "" if fleet.reconciler else " (the reconciler's status may be one of them)"
    said = (
        f"the broker dropped retained messages: {unknown} of {len(rows)} robots unknown"
        f"{reconciler}; raise its max_queued_messages (robotconf broker-config sets it for "
        f"the fleet). How it is known: {lost}"
    )
    return replace(fleet, rows=rows, lost=said)


def confirm_loss(
    view: RetainedView, fleet: FleetStatus, messages: dict[str, bytes], topics: Topics
) -> str | None:
    """Why the view's snapshot is known to be lossy, or None: the view's own account, else
    a few of the topics it lacks (the reconciler's status, assigned robots' statuses) read
    again alone: a fleet that is really off holds none of them."""
    if view.lost is None:
        silent = [
            topics.status(row.robot_id)
            for row in fleet.rows
            if row.verdict is Verdict.OFFLINE and topics.status(row.robot_id) not in messages
        ]
        if topics.reconciler_status not in messages:
            silent.insert(0, topics.reconciler_status)
        view.confirm_missing(silent, CONFIRM_TIMEOUT)
    return view.lost


def open_view(
    connection: Connection,
    prefix: str,
    on_change: Callable[[], None] | None = None,
    on_topic: Callable[[str], None] | None = None,
) -> RetainedView:
    """A (not yet started) view of every retained topic fleet status reads; `on_topic` is told
    each topic a message arrives on."""
    topics = Topics(prefix)
    return RetainedView(
        connection,
        subscriptions(Role.VIEWER, prefix),  # every topic `robotconf status` may read
        topics.sync,
        role="status",
        on_change=on_change,
        on_synced=on_change,
        on_topic=on_topic,
    )


def change_key(fleet: FleetStatus) -> str:
    """What tells one report from the next: a heartbeat alone is not a change."""
    return json.dumps(fleet.as_json(heartbeat=False), sort_keys=True)
