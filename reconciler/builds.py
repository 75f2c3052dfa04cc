"""The controller's builds (one owner: `Builds`): each commit built once, the last few kept, a
build that raised retried at the next resync, a request over an agent's size limit refused, and
the builds fleet.yaml stages keep.

A part of `reconciler.controller`'s state, kept apart so that the controller is a loop over
named parts rather than one class holding all of them.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable
from pathlib import Path

from robotconf.configurator.render import FleetRender
from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.launch import LaunchRequest
from robotconf.contract.safejson import MAX_PAYLOAD_BYTES
from robotconf.contract.wire import ReconcilerStatus, StatusDiagnostic, is_commit, short_rev
from robotconf.reconciler import heap
from robotconf.reconciler.decide import Reason
from robotconf.reconciler.desired import FLEET_FILE, Desired, DesiredBuilder
from robotconf.reconciler.rollout import stage_bases

log = logging.getLogger("robotconf.reconciler")

# A request the agents would refuse for its size is a build error, not a publish: the echo of
# an oversized message is dropped on arrival and would be republished at every pass. The
# margin leaves room for the signature.
MAX_REQUEST_BYTES = MAX_PAYLOAD_BYTES - 4096

Builder = Callable[[Path, str], Desired]


class Builds:
    """What commits ask for, built on the controller's loop only.

    `builder` turns a commit into what it asks for (by default a `DesiredBuilder`, whose
    cache lives as long as the controller; a seam for tests)."""

    def __init__(self, root: Path, builder: Builder | None = None) -> None:
        self._root = root
        self._builder = builder if builder is not None else DesiredBuilder()
        self._built: OrderedDict[str, Desired] = OrderedDict()
        self._sizes = RequestSizes()
        self._crashed: set[str] = set()  # revisions whose build raised: retried at each resync
        self._stage_built: dict[str, Desired] = {}  # revisions a stage keeps (`stage_builds`)

    def crashed(self, revision: str | None) -> bool:
        """Whether the build of `revision` raised (a bug, not the commit's fault)."""
        return revision in self._crashed

    def retry_crashed(self) -> None:
        """A build that raised is tried again, once an interval (at each resync)."""
        for revision in self._crashed:
            self._built.pop(revision, None)
        self._crashed.clear()

    def build(self, revision: str) -> Desired:
        """A commit never changes: build each one once (the last few are kept)."""
        built = self._built.get(revision)
        if built is None:
            started = time.monotonic()
            built = self.build_safely(revision)
            heap.release()  # what the build parsed and dropped
            log.info("built %s in %.3f s", short_rev(revision), time.monotonic() - started)
            self._built[revision] = built
            # The head and the revision served (a rollout's stable one): each kept build holds
            # a fleet's requests, and an incremental build of any other is cheap.
            while len(self._built) > 2:
                self._built.popitem(last=False)
        return built

    def build_safely(self, revision: str) -> Desired:
        """Whatever the commit holds, a Desired: a bug in the build makes it one with errors."""
        try:
            built = self._builder(self._root, revision)
        except Exception as exc:
            log.exception("internal error while building %s", short_rev(revision))
            self._crashed.add(revision)
            message = f"internal error while building {short_rev(revision)}: {type(exc).__name__}"
            problem = StatusDiagnostic(
                code=Reason.INTERNAL_ERROR.value, message=f"{message}: {exc}"[:500]
            )
            return Desired(revision, None, [problem])
        if built.fleet is None:
            return built
        # As kept: 10,000 requests are not stamped with the revision to be measured.
        requests, revision = built.fleet.requests.as_kept(), built.fleet.requests.revision
        measure = self._sizes.size
        over = [
            (robot_id, size)
            for robot_id, request in requests
            if (size := measure(request, revision)) > MAX_REQUEST_BYTES
        ]
        problems = [
            StatusDiagnostic(
                path=FLEET_FILE,
                code=Reason.BUILD_FAILED.value,
                message=f"the launch request of {robot_id} is {size:,} bytes, over the "
                f"{MAX_REQUEST_BYTES:,} an agent accepts; make its settings or environment "
                "knowledge smaller",
            )
            for robot_id, size in sorted(over)
        ]
        self._sizes.keep_only(request for _, request in requests)
        return Desired(revision, None, problems) if problems else built

    def stage_builds(
        self, build: Desired, previous: ReconcilerStatus | None, serving: Desired | None
    ) -> dict[str, FleetRender]:
        """fleet.yaml stages: the builds of the revisions the stages' robots keep
        (`stage_bases`, read from the retained rollout) other than the serving one; each built
        once and kept while a stage keeps it. One that cannot be built is left out: its stage
        keeps the serving revision."""
        fleet, rollout = build.fleet, previous.rollout if previous is not None else None
        if fleet is None or fleet.rollout is None or not fleet.stages or rollout is None:
            self._stage_built.clear()
            return {}
        served = serving.revision if serving is not None else None
        wanted = {
            base
            for base in stage_bases(fleet, rollout, served)
            if base is not None and base != served and is_commit(base)
        }
        for gone in self._stage_built.keys() - wanted:
            del self._stage_built[gone]
        found: dict[str, FleetRender] = {}
        for revision in wanted:
            made = build if revision == build.revision else self._stage_built.get(revision)
            if made is None:
                made = self._stage_built[revision] = self.build_safely(revision)
            if made.fleet is not None:
                found[revision] = made.fleet
        return found


class RequestSizes:
    """The published size of each request, worked out once per content: requests with one
    digest differ only in their revision (a commit id: letters and digits, written as they are
    in JSON), so a commit that changes ten robots serialises ten requests to check their size,
    not the whole fleet."""

    def __init__(self) -> None:
        self._without_revision: dict[str, int] = {}

    def size(self, request: RenderedRequest | LaunchRequest, revision: str | None = None) -> int:
        """`revision`: the one the request is published with, when not its own (a request a
        fleet kept from an earlier commit: FleetRequests)."""
        own = request.revision
        target = own if revision is None else revision
        if not (_plain(own) and _plain(target)):  # escapes would make its length another
            if target != own:
                assert isinstance(request, RenderedRequest)
                request = request.with_revision(target)
            return len(request.payload())
        base = self._without_revision.get(request.digest)
        if base is None:
            base = len(request.payload()) - len(own)
            self._without_revision[request.digest] = base
        return base + len(target)

    def keep_only(self, requests: Iterable[RenderedRequest | LaunchRequest]) -> None:
        digests = {r.digest for r in requests}
        self._without_revision = {d: n for d, n in self._without_revision.items() if d in digests}


def _plain(revision: str) -> bool:
    """Written in JSON as it is (a commit id: letters and digits)."""
    return revision.isascii() and revision.isalnum()
