"""`robotconf reconcile`, `status` and `up`: arguments in, one clear line out on any trouble."""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from configurator.mqtt import Connection
from configurator.render import RenderError, render_fleet
from configurator.signing import Signed, SigningKeyError
from configurator.source import SourceError
from configurator.wire import DEFAULT_BROKER, ReconcilerStatus, Topics, validate_prefix
from configurator.workspace import check
from reconciler.observed import parse_retained
from reconciler.retained import RetainedView
from reconciler.source import BranchSource, LocalBranch, RemoteBranch
from reconciler.status import (
    DesiredRobot,
    FleetStatus,
    build_rows,
    desired_from_fleet,
    desired_from_retained,
    format_text,
    short_rev,
)

if TYPE_CHECKING:
    from reconciler.controller import Signer

EXIT_OK, EXIT_FINDINGS, EXIT_TOOL = 0, 1, 2


class UsageError(Exception):
    """A problem the user can fix; printed as one line, exit 2."""


def connection_from(args: argparse.Namespace, url: str | None = None) -> Connection:
    connection = Connection(
        url=url or args.broker or DEFAULT_BROKER,
        username=args.username,
        password_file=args.password_file,
        ca_file=args.ca_file,
        cert_file=args.cert_file,
        key_file=args.key_file,
        insecure=args.insecure,
    )
    try:
        connection.address  # noqa: B018 - validates the URL now, not in a network thread
        validate_prefix(args.prefix)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if connection.password_file is not None:
        try:
            connection.password()
        except OSError as exc:
            raise UsageError(
                f"cannot read --password-file {connection.password_file}: {exc.strerror}"
            ) from None
    return connection


def _fail(message: str) -> int:
    print(f"robotconf: {message}", file=sys.stderr)
    return EXIT_TOOL


def on_stop_signals(
    stop: threading.Event | None = None, callback: Callable[[], None] | None = None
) -> None:
    """SIGINT and SIGTERM end the command cleanly instead of raising in a random place."""

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop is not None:
            stop.set()
        if callback is not None:
            callback()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def _log_to_stderr(name: str) -> None:
    logging.basicConfig(
        level=logging.INFO,
        format=f"%(asctime)s {name} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    logging.getLogger("watchfiles").setLevel(logging.WARNING)  # it logs every change it sees


# ------------------------------------------------------------------ reconcile


def make_source(args: argparse.Namespace) -> BranchSource:
    if args.remote:
        cache = Path(args.cache_dir) if getattr(args, "cache_dir", None) else None
        return RemoteBranch(args.remote, args.branch, cache)
    source = LocalBranch(args.repo, args.branch)
    source.head()  # a branch that does not exist is a typo: say so now
    return source


def make_signer(key_path: Path | None) -> Signer | None:
    """A function that signs launch and stop requests with the key, or None when signing is off."""
    if key_path is None:
        return None
    from configurator.signing import load_private_key, sign

    key = load_private_key(key_path)

    def signer(request: Signed) -> Signed:
        return sign(request, key)

    return signer


def cmd_reconcile(args: argparse.Namespace) -> int:
    from reconciler.controller import Controller

    try:
        connection = connection_from(args)
        if args.interval <= 0:
            raise UsageError("--interval must be a positive number of seconds")
        source = make_source(args)
    except (UsageError, SourceError) as exc:
        return _fail(str(exc))
    try:
        signer = make_signer(args.signing_key)
    except SigningKeyError as exc:
        return _fail(str(exc))
    _log_to_stderr("reconciler")
    controller = Controller(source, connection, args.prefix, args.interval, signer=signer)
    on_stop_signals(callback=controller.stop)
    logging.getLogger("robotconf.reconciler").info(
        "reconciling %s (branch %s) to %s, prefix %s",
        source.description,
        args.branch,
        connection.address.url,
        args.prefix,
    )
    controller.run()
    return EXIT_OK


# ------------------------------------------------------------------ status


class DesiredCache:
    """The desired robots for `status`, re-read only when the revision to compare with moves."""

    def __init__(self, repo: Path, rev: str | None) -> None:
        self.repo = repo
        self.rev = rev
        self._key: tuple[str | None, str | None] | None = None
        self._value: tuple[dict[str, DesiredRobot] | None, str, list[str]] = ({}, "", [])

    def get(
        self, reconciler: ReconcilerStatus | None
    ) -> tuple[dict[str, DesiredRobot] | None, str, list[str]]:
        applied = reconciler.last_applied_revision if reconciler else None
        key = (self.rev, applied)
        if key != self._key:
            self._value = self._load(applied)
            self._key = key
        return self._value

    def _load(self, applied: str | None) -> tuple[dict[str, DesiredRobot] | None, str, list[str]]:
        notes: list[str] = []
        # What the reconciler applied is what robots should run; the work tree is the fallback.
        candidates: list[str | None] = (
            [self.rev] if self.rev else [applied, None] if applied else [None]
        )
        for rev in candidates:
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
            return desired_from_fleet(fleet), where, notes
        return None, "the retained launch topics (no valid repository to compare with)", notes


def fleet_status(messages: dict[str, bytes], topics: Topics, desired: DesiredCache) -> FleetStatus:
    retained = parse_retained(messages, topics)
    robots, where, notes = desired.get(retained.reconciler)
    if robots is None:
        robots = desired_from_retained(retained)
    rows = build_rows(robots, retained)
    return FleetStatus(rows, retained.reconciler, where, list(notes), retained.ignored)


def open_view(
    connection: Connection, prefix: str, on_change: Callable[[], None] | None = None
) -> RetainedView:
    topics = Topics(prefix)
    return RetainedView(
        connection,
        [topics.all_launch, topics.all_status, topics.all_description, topics.reconciler_status],
        f"{prefix}/sync",
        role="status",
        on_change=on_change,
        on_synced=on_change,
    )


def cmd_status(args: argparse.Namespace) -> int:
    try:
        connection = connection_from(args)
    except UsageError as exc:
        return _fail(str(exc))
    topics = Topics(args.prefix)
    desired = DesiredCache(args.repo, args.rev)
    changed = threading.Event()
    view = open_view(connection, args.prefix, changed.set)
    view.start()
    try:
        if not view.wait_synced(args.wait):
            reason = view.last_error or "no answer"
            return _fail(
                f"no retained messages from {connection.address.url} within {args.wait:g} s "
                f"({reason}); is the broker running? (--broker URL, --wait S)"
            )
        if not args.watch:
            fleet = fleet_status(view.snapshot(), topics, desired)
            _show(fleet, args.json, clear=False)
            return EXIT_OK if fleet.in_sync else EXIT_FINDINGS
        return _watch(view, topics, desired, changed, args.json)
    finally:
        view.stop()


def _show(fleet: FleetStatus, as_json: bool, *, clear: bool) -> None:
    if as_json:
        sys.stdout.write(json.dumps(fleet.as_json(), indent=None if clear else 2) + "\n")
    else:
        text = format_text(fleet)
        if clear:
            text = "\x1b[H\x1b[2J" + text
        sys.stdout.write(text)
    sys.stdout.flush()


def _watch(
    view: RetainedView,
    topics: Topics,
    desired: DesiredCache,
    changed: threading.Event,
    as_json: bool,
) -> int:
    stop = threading.Event()
    on_stop_signals(stop, changed.set)
    tty = sys.stdout.isatty() and not as_json
    shown: str | None = None
    code = EXIT_FINDINGS
    while not stop.is_set():
        changed.clear()
        if view.synced:
            fleet = fleet_status(view.snapshot(), topics, desired)
            code = EXIT_OK if fleet.in_sync else EXIT_FINDINGS
            # A heartbeat alone is not a change worth a new report.
            key = json.dumps(fleet.as_json(heartbeat=False)) if as_json else format_text(fleet)
            if key != shown:
                if as_json:
                    print(json.dumps(fleet.as_json()), flush=True)
                else:
                    _show(fleet, False, clear=tty)
                    if not tty:
                        print("---", flush=True)
                shown = key
        elif not as_json and shown != "offline":
            print(f"(waiting for the broker at {view.connection.address.url}: {view.last_error})")
            shown = "offline"
        changed.wait(5.0)
        time.sleep(0.2)  # coalesce a burst of status messages into one redraw
    return code


# ------------------------------------------------------------------ up


def cmd_up(args: argparse.Namespace) -> int:
    from reconciler.up import run_up

    return run_up(args)
