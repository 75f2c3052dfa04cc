"""The controller's delivery (one owner: `Delivery`): a decision's launch requests published,
signed as they are sent, and the topics no longer assigned cleared (or given a signed stop),
all retained, through the launch view; the outcome is what the broker acknowledged.

A part of `reconciler.controller`'s state, kept apart so that the controller is a loop over
named parts rather than one class holding all of them.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Protocol

from robotconf.configurator.rendered import RenderedRequest
from robotconf.contract.launch import StopRequest
from robotconf.contract.signing import Signed
from robotconf.contract.wire import Topics, short_rev
from robotconf.readmodel.observed import launch_summary
from robotconf.readmodel.retained import Payload, RetainedView
from robotconf.reconciler import heap
from robotconf.reconciler.decide import Condition, Decision

log = logging.getLogger("robotconf.reconciler")


class Signer(Protocol):
    """Signs a launch or a stop request (contract.signing.sign with the reconciler's key)."""

    def __call__(self, request: Signed, /) -> Signed: ...


class Delivery:
    """Publishes through `view` (the launch view), each batch within `timeout` seconds."""

    def __init__(
        self, view: RetainedView, topics: Topics, signer: Signer | None, timeout: float
    ) -> None:
        self._view = view
        self._topics = topics
        self._sign = signer
        self._timeout = timeout

    @property
    def signs(self) -> bool:
        """Whether what it publishes is signed."""
        return self._sign is not None

    def publish(self, decision: Decision) -> Condition:
        """Publishes what differs and clears what is no longer assigned; the outcome."""
        actions, target = decision.actions, decision.target
        assert actions is not None and target is not None
        started = time.monotonic()
        # Signed at publish time: issued_at is when the robot was told, not when it was built.
        # Each payload is made as it is sent (`Payload`): 10,000 are never held at once.
        sign = self._sign
        items: list[tuple[str, Payload]] = [
            (self._topics.launch(r), _signed(sign, req) if sign else req.payload)
            for r, req in actions.publish.items()
        ]
        # What the view keeps of each request is known without reading it back; a Stop's,
        # the view's own `keep` works out.
        kept: list[bytes | None] = [
            launch_summary("LaunchRequest", req.digest, sign is not None)
            for req in actions.publish.values()
        ]
        for r in actions.clear:
            items.append((self._topics.launch(r), self._stop_payload(r, target.revision)))
            kept.append(None)
        publishing = time.monotonic()
        acknowledged = self._view.publish_retained(items, self._timeout, kept)
        done = time.monotonic()
        del items, kept  # 10,000 payloads: freed, then given back to the system
        heap.release()
        if not acknowledged:
            return decision.unacknowledged(self._view.last_error)
        log.info(
            "applied %s: %d published, %d cleared, %d unchanged%s (%.3f s; publishing, first "
            "message to last PUBACK, %.3f s)",
            short_rev(target.revision),
            len(actions.publish),
            len(actions.clear),
            actions.unchanged,
            f", {len(actions.held)} suspended left as they are" if actions.held else "",
            done - started,
            done - publishing,
        )
        return decision.condition

    def _stop_payload(self, robot_id: str, revision: str) -> bytes:
        """Empty (docs/architecture.md#the-mqtt-contract), or a signed StopRequest when requests
        are signed: an agent that verifies requests stops only for a stop it can verify."""
        if self._sign is None:
            return b""
        return self._sign(StopRequest(robot_id=robot_id, revision=revision)).payload()


def _signed(sign: Signer, request: RenderedRequest) -> Callable[[], bytes]:
    """What makes the request's signed payload when it is sent."""
    return lambda: sign(request.model()).payload()
