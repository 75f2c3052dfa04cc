"""Pure diff: desired requests vs the retained launch topics -> what to publish, clear, leave."""

from __future__ import annotations

from collections.abc import Mapping, Set
from dataclasses import dataclass, field
from typing import Generic, Protocol, TypeVar

from robotconf.configurator.rendered import FleetRequests


class HasDigest(Protocol):
    @property
    def digest(self) -> str: ...


R = TypeVar("R", bound=HasDigest)


@dataclass
class Actions(Generic[R]):
    """One reconcile step. `refused` set: do nothing at all, and say why."""

    publish: dict[str, R] = field(default_factory=dict)
    clear: list[str] = field(default_factory=list)
    held: list[str] = field(default_factory=list)  # suspended robots whose topic differs
    unchanged: int = 0
    refused: str | None = None

    @property
    def empty(self) -> bool:
        return not self.publish and not self.clear


def diff(
    desired: Mapping[str, R],
    observed: Mapping[str, str | None],
    suspended: Set[str] = frozenset(),
    allow_empty: bool = False,
    running: Set[str] = frozenset(),
    unsigned: Set[str] = frozenset(),
) -> Actions[R]:
    """`observed`: robot -> digest of its retained launch (None: retained but unreadable).

    Robots absent from `observed` have nothing retained. Suspended robots are left exactly as
    they are, even when nothing is published for them yet. `running`: robots whose agent says
    it runs a brain; one that is no longer assigned is cleared again, because a clear (an
    empty retained message) is not kept by the broker and an agent that was offline then
    never saw it. `unsigned`: robots whose retained request carries no signature while the
    reconciler signs; each is published again, signed, though its digest is the same (an
    agent that verifies refuses the unsigned one, and would wait for the next change).
    """
    actions: Actions[R] = Actions()
    # A fleet's requests are stamped with its revision as they are read: only the ones
    # published are (FleetRequests.digests).
    digests = (
        desired.digests()
        if isinstance(desired, FleetRequests)
        else {robot_id: request.digest for robot_id, request in desired.items()}
    )
    differ = [
        robot_id
        for robot_id, digest in digests.items()
        if observed.get(robot_id) != digest or robot_id in unsigned
    ]
    actions.unchanged = len(digests) - len(differ)
    for robot_id in sorted(differ):  # sorted: what differs, not the whole fleet
        if robot_id in suspended:
            actions.held.append(robot_id)
        else:
            actions.publish[robot_id] = desired[robot_id]
    actions.clear = sorted(r for r in set(observed) | set(running) if r not in desired)
    if not desired and actions.clear and not allow_empty:
        return Actions(
            refused=(
                f"the commit assigns no robot and would stop all {len(actions.clear)} running; "
                "refused (set 'allow_empty: true' in configs/fleet.yaml to really empty the fleet)"
            )
        )
    return actions
