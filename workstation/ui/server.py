"""The UI's HTTP service: a route table answered on the bounded edge (readmodel/http_edge.py),
every page with the Content-Security-Policy, every bad request a 4xx page, never a traceback."""

from __future__ import annotations

import ipaddress
import logging
import re
import ssl
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from typing import TypeVar
from urllib.parse import unquote, urlsplit

from robotconf.contract.interfaces import MAX_INTERFACES_BYTES, RobotInterfaces
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.models import is_robot_id
from robotconf.contract.textsafe import printable
from robotconf.readmodel.http_edge import BoundedHTTPServer, FedStream, Limits, Request, Response
from robotconf.readmodel.retained import read_object
from robotconf.readmodel.timeline import QueryRefused
from robotconf.workstation.ui.auth import ANONYMOUS, Identity, OperatorAuth
from robotconf.workstation.ui.changes import Shown
from robotconf.workstation.ui.commit_facts import commit_section
from robotconf.workstation.ui.commit_reader import CommitError, CommitReader
from robotconf.workstation.ui.model import QueryError, parse_query
from robotconf.workstation.ui.pages import error_page, fleet_page
from robotconf.workstation.ui.revision_page import revision_page
from robotconf.workstation.ui.revisions import REVISION, EventLog, HistoryError, RevisionHistory
from robotconf.workstation.ui.robot_page import robot_page
from robotconf.workstation.ui.state import LiveFleet
from robotconf.workstation.ui.timeline_page import timeline_page, timeline_query

log = logging.getLogger("robotconf.ui")

CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "connect-src 'self'; form-action 'self'; frame-ancestors 'none'; base-uri 'none'"
)
SECURITY_HEADERS = (
    ("Content-Security-Policy", CSP),
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "same-origin"),
    ("X-Frame-Options", "DENY"),
)
HTML = "text/html; charset=utf-8"
STATIC = {"ui.js": "text/javascript; charset=utf-8", "ui.css": "text/css; charset=utf-8"}
# A browser opens a few connections per page and one event stream per open page: 32 per
# address is a few tabs; 256 in all. A form's body is a token or a CSRF field: 16 KB is plenty.
LIMITS = Limits(
    connections=256,
    per_client=32,
    head=5.0,
    silence=5.0,
    deadline=10.0,
    max_body=16 * 1024,
    body_methods=frozenset({"POST"}),
    stream_buffer=1024 * 1024,  # a reset event of 500 rows is about 300 KB
    stream_drain=10.0,
    stream_idle=15.0,
)
STREAM_BACKLOG = 32  # events waiting for one slow page before its stream ends (it reconnects)
RETRY_MS = 2000  # how soon a browser reconnects a stream that ended

Handler = Callable[[Request, "re.Match[str]", Identity], Response]


@dataclass(frozen=True)
class Route:
    """`handler` answers `method` requests whose path (percent-decoded) matches `pattern` whole."""

    method: str
    pattern: re.Pattern[str] | str
    handler: Handler


def html(code: int, text: str, *headers: tuple[str, str]) -> Response:
    return Response(code, text.encode("utf-8"), HTML, (("Cache-Control", "no-store"), *headers))


class UiService:
    """The edge's Service for `robotconf ui`: the read routes here, the write side's added."""

    def __init__(
        self,
        live: LiveFleet,
        auth: OperatorAuth,
        extra: Sequence[Route] = (),
        hosts: frozenset[str] | None = None,
    ) -> None:
        self.live = live
        self.auth = auth
        # The Host headers answered (None: any): on loopback, only loopback names, so that a
        # web page whose name an attacker points at 127.0.0.1 (DNS rebinding) reads nothing.
        self.hosts = hosts
        self.static = {name: _static(name) for name in STATIC}
        # The write side's: a robot's latest restart outcome (HTML) for an operator's page.
        self.restart_outcome: Callable[[str], str] = lambda robot_id: ""
        # The reconciler's outcome ledger, for the revision pages; None: not open here.
        self.history: RevisionHistory | None = None
        # The repository's commits, for the revision pages; None: no repository here.
        self.commits: CommitReader | None = None
        self.timeline: EventLog | None = None  # the same ledger's events, for /timeline
        self.no_history = (
            "No outcome ledger is open here: it is the reconciler's (robotconf ui --state-dir "
            "DIR names its state folder; reconcile --ui and up --ui read their own)."
        )
        self.routes: list[Route] = [
            Route("GET", r"/", self.fleet),
            Route("GET", r"/healthz", self.healthz),
            Route("GET", r"/events", self.events),
            Route("GET", r"/static/(?P<name>[^/]{1,64})", self.file),
            Route("GET", r"/favicon\.ico", self.no_icon),
            Route("GET", r"/robots/(?P<robot>[^/]{1,200})", self.robot),
            Route("GET", r"/revisions/(?P<rev>[^/]{1,200})", self.revision),
            Route("GET", r"/timeline", self.timeline_view),
            *extra,
        ]

    # ------------------------------------------------------------------ the edge's Service

    def answer(self, request: Request) -> Response:
        return _secured(self._answer(request))

    def refused(self, request: Request, code: int, message: str) -> Response:
        return _secured(Response.text(code, message))

    def _answer(self, request: Request) -> Response:
        if not request.target.startswith("/"):
            return self.error(400, "the request target is not a path")
        host = (request.headers.get("Host") or "").strip().lower()
        if self.hosts is not None and host and host not in self.hosts:
            return self.error(421, "this server answers to its loopback address only")
        parts = urlsplit(request.target)
        try:
            path = unquote(parts.path, errors="strict")
        except UnicodeDecodeError:
            return self.error(400, "the path is not UTF-8 once decoded")
        try:
            who = self.auth.identify(request.headers, request.client)
        except Exception as exc:  # a bug in telling who it is: a viewer, never a traceback
            log.error("ui: identifying a request failed: %s", printable(str(exc))[:200])
            who = ANONYMOUS
        allowed = []
        for route in self.routes:
            found = re.fullmatch(route.pattern, path)
            if found is None:
                continue
            if route.method == request.method or (route.method, request.method) == ("GET", "HEAD"):
                return route.handler(request, found, who)
            allowed.append(route.method)
        if allowed:
            names = ", ".join(sorted(set(allowed)))
            return self.error(
                405, f"{printable(request.method)} is not {names}", who, ("Allow", names)
            )
        return self.error(404, "no such page", who)

    def error(
        self, code: int, message: str, who: Identity = ANONYMOUS, *headers: tuple[str, str]
    ) -> Response:
        return html(code, error_page(code, message, who), *headers)

    # ------------------------------------------------------------------ read routes

    def fleet(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        try:
            query, _ = parse_query(urlsplit(request.target).query)
        except QueryError as exc:
            return self.error(exc.code, str(exc), who)
        return html(200, fleet_page(self.live.snapshot, query, who))

    def healthz(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        return Response.text(200, "ok")

    def robot(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        robot_id = match["robot"]
        if not is_robot_id(robot_id):
            return self.error(400, "that is not a robot id", who)
        snap = self.live.snapshot
        if snap.fleet is not None and snap.row(robot_id) is None:
            return self.error(404, f"no robot {robot_id} in the fleet or on the broker", who)
        topics = self.live.topics
        launch = _parsed(self.live.payload(topics.launch(robot_id)), LaunchRequest)
        interfaces = _parsed(
            self.live.payload(topics.interfaces(robot_id)), RobotInterfaces, MAX_INTERFACES_BYTES
        )
        outcome = self.restart_outcome(robot_id) if who.operator else ""
        return html(200, robot_page(snap, robot_id, who, launch, interfaces, outcome))

    def revision(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        """What a revision achieved beside the one before it (the ledger's), and what its
        robots report now (their retained goals summaries)."""
        revision = match["rev"].lower()
        if not REVISION.fullmatch(revision):
            return self.error(400, "a revision is a commit id: 4 to 64 hexadecimal digits", who)
        kept, why = None, None
        if self.history is None:
            why = self.no_history
        else:
            try:
                kept = self.history.compare(revision)
            except HistoryError as exc:
                why = f"The outcome ledger cannot be read: {exc}"
            except Exception as exc:  # a bug in reading it: said, the live part still shown
                log.error(
                    "ui: the ledger's answer for %s failed: %s", revision, printable(str(exc))[:300]
                )
                why = "The outcome ledger could not be read (the UI's log says why)."
        commit = self._commit(revision)
        return html(200, revision_page(self.live.snapshot, revision, who, kept, why, commit))

    def _commit(self, revision: str) -> str:
        """The page's commit section: the commit's facts and plan, or why they are not shown."""
        if self.commits is None:
            return commit_section(None, "No repository is open here.")
        try:
            return commit_section(self.commits.read(revision))
        except CommitError as exc:
            return commit_section(None, str(exc))

    def timeline_view(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        """The fleet's events kept in the ledger, newest first, narrowed by the query string."""
        try:
            query, typed = timeline_query(urlsplit(request.target).query, time.time())
        except QueryRefused as exc:
            return self.error(400, str(exc), who)
        found, why = None, None
        if self.timeline is None:
            why = self.no_history
        else:
            try:
                found = self.timeline.events(query)
            except HistoryError as exc:
                why = f"The ledger cannot be read: {exc}"
            except Exception as exc:  # a bug in reading it: said, never a traceback
                log.error("ui: the ledger's events failed: %s", printable(str(exc))[:300])
                why = "The ledger could not be read (the UI's log says why)."
        return html(200, timeline_page(query, typed, who, found, why))

    def events(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        """The page's server-sent events: what changed, from the page's own state on."""
        try:
            query, other = parse_query(urlsplit(request.target).query)
        except QueryError as exc:
            return self.error(exc.code, str(exc), who)
        robot = other.get("robot")
        if robot is not None and not is_robot_id(robot):
            return self.error(400, "that is not a robot id", who)
        version = _version(request.headers.get("Last-Event-ID") or other.get("v"))
        if request.method == "HEAD":
            return Response(200, b"", "text/event-stream")
        key: list[int] = []

        def closed() -> None:
            for k in key:
                self.live.unsubscribe(k)

        stream = FedStream(STREAM_BACKLOG, on_close=closed)
        found = self.live.subscribe(Shown(query, robot), stream, version)
        if found is None:
            return self.error(503, "too many pages are open", who, ("Retry-After", "10"))
        key.append(found)
        return Response(
            200,
            f"retry: {RETRY_MS}\n\n".encode(),
            "text/event-stream; charset=utf-8",
            (("X-Accel-Buffering", "no"),),
            stream=stream,
            keepalive=b": keep-alive\n\n",
        )

    def no_icon(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        """Browsers ask for it: nothing, rather than a 404 in their console."""
        return Response(204)

    def file(self, request: Request, match: re.Match[str], who: Identity) -> Response:
        name = match["name"]
        if name not in self.static:
            return self.error(404, "no such file", who)
        return Response(200, self.static[name], STATIC[name], (("Cache-Control", "no-cache"),))


def loopback_hosts(port: int) -> frozenset[str]:
    """The Host headers a loopback listener on `port` answers."""
    names = ("127.0.0.1", "localhost", "[::1]")
    return frozenset({*names, *(f"{name}:{port}" for name in names)})


def is_loopback(host: str) -> bool:
    """A host name or address only this machine reaches."""
    try:
        return host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _secured(response: Response) -> Response:
    """Every answer with the security headers (a page's CSP above all)."""
    names = {name.lower() for name, _ in response.headers}
    extra = tuple(h for h in SECURITY_HEADERS if h[0].lower() not in names)
    return Response(
        response.code,
        response.body,
        response.content_type,
        (*response.headers, *extra),
        response.stream,
        response.keepalive,
    )


def _version(text: str | None) -> int | None:
    if text is None or not text.isdigit() or len(text) > 18:
        return None
    return int(text)


M = TypeVar("M", LaunchRequest, RobotInterfaces)


def _parsed(payload: bytes | None, model: type[M], limit: int | None = None) -> M | None:
    """What a retained payload holds, or None when it cannot be read as `model`."""
    if not payload:
        return None
    try:
        raw = read_object(payload) if limit is None else read_object(payload, limit)
        return model.model_validate(raw)
    except Exception:  # unreadable, oversized, another kind (a Stop): none to show
        return None


def _static(name: str) -> bytes:
    return (resources.files("robotconf.workstation.ui") / "static" / name).read_bytes()


def serve(
    service: UiService, host: str, port: int, tls: ssl.SSLContext | None = None
) -> BoundedHTTPServer:
    """Listens now (OSError when it cannot) and answers on a thread of its own; on loopback,
    to loopback names only."""
    if is_loopback(host):
        service.hosts = loopback_hosts(port)
    edge = BoundedHTTPServer("ui", service, LIMITS)
    edge.listen(host, port, tls)
    return edge
