"""What judging a rollout's wave costs the reconciler at fleet scale: one `roll_out` step (pure,
no broker) over N robots, and the size of the wave record it keeps retained.

For each size, a fleet of N robots moves from one revision to the next in two waves (a 1%
canary, then all): the step that publishes the last wave, steps while its robots become
healthy one share at a time, and the step that completes it. Each step starts from the record
the previous step returned, decoded and encoded again as a restarted reconciler would. Medians
of --rounds runs per step kind.

    python bench/wave_step.py [--sizes 1000,10000] [--rounds 7]
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

from robotconf.configurator.render import FleetRender
from robotconf.configurator.types import RolloutPolicy, Wave
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.reconciler.rollout import RolloutInput, RolloutStep, roll_out

T0 = 1_000_000.0


class Request:
    """What a rollout reads of a rendered request: its digest."""

    def __init__(self, digest: str) -> None:
        self.digest = digest


def fleet(robots: list[str], version: str, policy: RolloutPolicy) -> FleetRender:
    requests: Any = {r: Request(f"sha256:{version}{r}") for r in robots}
    labels = {r: ({"ring": "canary"} if i % 100 == 0 else {}) for i, r in enumerate(robots)}
    return FleetRender(version * 40, requests, labels=labels, rollout=policy)


def statuses(head: FleetRender, robots: list[str], healthy: set[str]) -> dict[str, AgentStatus]:
    return {
        r: AgentStatus(
            robot_id=r,
            state=AgentState.RUNNING,
            digest=head.requests[r].digest if r in healthy else "sha256:old",
            pid=1000 + i,
        )
        for i, r in enumerate(robots)
    }


def timed(seen: RolloutInput) -> tuple[float, RolloutStep]:
    started = time.perf_counter()
    step = roll_out(seen)
    return time.perf_counter() - started, step


def run(size: int, rounds: int) -> None:
    policy = RolloutPolicy(
        waves=[Wave(name="canary", selector={"ring": "canary"}), Wave(name="all")],
        healthy_after=10,
        wave_timeout=600,
    )
    robots = [f"tb3-{i:05d}" for i in range(size)]
    stable, head = fleet(robots, "a", policy), fleet(robots, "b", policy)
    held = {r: head.requests[r].digest for r in robots}
    kinds: dict[str, list[float]] = {"publish last wave": [], "judge": [], "complete": []}
    record_bytes = 0
    for _ in range(rounds):
        all_new = statuses(head, robots, set(robots))
        canary = [r for r in robots if head.labels[r]]
        begin = RolloutInput(
            head,
            stable,
            None,
            {r: stable.requests[r].digest for r in robots},
            statuses(head, robots, set()),
            {},
            T0,
            None,
            T0,
        )
        first = roll_out(begin)
        since = dict.fromkeys(canary, T0)
        gate = RolloutInput(
            head,
            stable,
            first.status,
            {**begin.launches, **{r: held[r] for r in canary}},
            statuses(head, robots, set(canary)),
            since,
            T0 + 10,
            first.record,
            T0,
        )
        seconds, step = timed(gate)
        kinds["publish last wave"].append(seconds)
        # The last wave becomes healthy a tenth at a time.
        for tenth in range(1, 10):
            healthy = set(robots[: size * tenth // 10])
            since = dict.fromkeys(healthy, T0 + 10)
            seconds, step = timed(
                RolloutInput(
                    head,
                    stable,
                    step.status,
                    held,
                    statuses(head, robots, healthy),
                    since,
                    T0 + 20 + tenth,
                    step.record,
                    T0,
                )
            )
            kinds["judge"].append(seconds)
            if step.record is not None:
                record_bytes = len(step.record.model_dump_json())
        seconds, done = timed(
            RolloutInput(
                head,
                stable,
                step.status,
                held,
                all_new,
                dict.fromkeys(robots, T0 + 10),
                T0 + 40,
                step.record,
                T0,
            )
        )
        kinds["complete"].append(seconds)
        assert done.complete, done.status
    for kind, values in kinds.items():
        print(f"{size:>6} robots  {kind:<18} median {statistics.median(values) * 1000:8.1f} ms")
    print(f"{size:>6} robots  wave record        {record_bytes:,} bytes (retained)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1000,10000")
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    for size in (int(s) for s in args.sizes.split(",")):
        run(size, args.rounds)


if __name__ == "__main__":
    main()
