"""What changed for one open page between two states, as its server-sent event, pure: changed
rows with their rank, removed ids, boxes whose HTML changed; a reset when it cannot catch up."""

from __future__ import annotations

import json
from collections.abc import Set
from dataclasses import dataclass, field

from robotconf.readmodel.verdicts import RobotRow
from robotconf.workstation.ui.goals_html import goals_box, rates_box
from robotconf.workstation.ui.model import FleetQuery, Snapshot, Visible, rank, visible
from robotconf.workstation.ui.pages import (
    banner_box,
    reconciler_box,
    rollout_box,
    row_html,
    summary_box,
)
from robotconf.workstation.ui.robot_page import robot_box

EVENT = "fleet"  # the name of every event the stream sends


@dataclass
class Shown:
    """What one open page shows: kept per event stream, to send it only what changed."""

    query: FleetQuery
    robot: str | None = None  # a robot's page: its box, no rows
    rows: set[str] = field(default_factory=set)
    boxes: dict[str, str] = field(default_factory=dict)


class Views:
    """What the pages of one state show, worked out once per query and rows rendered once:
    many open pages of the same query cost one scan of the fleet, not one each."""

    def __init__(self, snap: Snapshot) -> None:
        self.snap = snap
        self._seen: dict[tuple[FleetQuery, str | None], Visible | None] = {}
        self._boxes: dict[tuple[FleetQuery, str | None], dict[str, str]] = {}
        self._rows: dict[str, str] = {}

    def seen(self, shown: Shown) -> Visible | None:
        key = (shown.query, shown.robot)
        if key not in self._seen:
            snap = self.snap
            fleet = snap.fleet
            self._seen[key] = (
                None if shown.robot is not None or fleet is None else visible(fleet, shown.query)
            )
        return self._seen[key]

    def boxes(self, shown: Shown) -> dict[str, str]:
        """The page's live boxes as HTML, by their `data-box` name."""
        key = (shown.query, shown.robot)
        if key not in self._boxes:
            snap = self.snap
            if shown.robot is not None:
                made = {
                    "banner": banner_box(snap),
                    "robot": robot_box(snap, shown.robot),
                    "goals": goals_box(snap, shown.robot),
                }
            else:
                made = {
                    "banner": banner_box(snap),
                    "reconciler": reconciler_box(snap),
                    "rollout": rollout_box(snap),
                    "summary": summary_box(self.seen(shown), shown.query),
                    "rates": rates_box(snap, shown.query),
                }
            self._boxes[key] = made
        return self._boxes[key]

    def row(self, row: RobotRow) -> list[str]:
        """[id, rank, html] of a row, as an event carries it."""
        if row.robot_id not in self._rows:
            self._rows[row.robot_id] = row_html(row)
        return [row.robot_id, rank(row), self._rows[row.robot_id]]


def first(
    snap: Snapshot, shown: Shown, page_version: int | None, views: Views | None = None
) -> bytes | None:
    """A stream's first event: none when its page was made from this very state; else a reset
    (the page's rows and boxes replaced). `shown` is updated to what the page then shows."""
    views = views if views is not None else Views(snap)
    seen = views.seen(shown)
    rows = seen.rows if seen is not None else []
    shown.rows = {row.robot_id for row in rows}
    shown.boxes = views.boxes(shown)
    if page_version == snap.version:
        return None
    message = {
        "v": snap.version,
        "reset": True,
        "rows": [views.row(row) for row in rows],
        "removed": [],
        "boxes": shown.boxes,
    }
    return event(snap.version, message)


def change(
    snap: Snapshot, shown: Shown, changed: Set[str], views: Views | None = None
) -> bytes | None:
    """The event that brings a page showing `shown` to `snap`, or None when nothing it shows
    changed; `changed`: the robots whose rows differ from the state before."""
    views = views if views is not None else Views(snap)
    seen = views.seen(shown)
    rows = seen.rows if seen is not None else []
    sent = [
        views.row(row) for row in rows if row.robot_id in changed or row.robot_id not in shown.rows
    ]
    now = {row.robot_id for row in rows}
    removed = sorted(shown.rows - now)
    shown.rows = now
    current = views.boxes(shown)
    moved = {name: text for name, text in current.items() if shown.boxes.get(name) != text}
    shown.boxes = current
    if not sent and not removed and not moved:
        return None
    message = {"v": snap.version, "reset": False, "rows": sent, "removed": removed, "boxes": moved}
    return event(snap.version, message)


def event(version: int, message: dict[str, object]) -> bytes:
    """One server-sent event: JSON on one line (json.dumps writes no raw newline)."""
    data = json.dumps(message, separators=(",", ":"))
    return f"id: {version}\nevent: {EVENT}\ndata: {data}\n\n".encode()


def changed_rows(before: Snapshot | None, after: Snapshot) -> set[str]:
    """Robots whose row differs between two states (all of them without a state before)."""
    if before is None:
        return set(after.by_id)
    old = before.by_id
    found = {robot_id for robot_id, row in after.by_id.items() if old.get(robot_id) != row}
    return found | (set(old) - set(after.by_id))
