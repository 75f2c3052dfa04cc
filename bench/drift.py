"""What judging drift costs at fleet scale: N robots with requests and interfaces reports, one
robot's interfaces changing, judged incrementally (the memo `status --watch` and the
reconciler's alerts keep) beside a full comparison of the fleet. Pure: no broker.

Each robot runs one of the example lab's scenarios in a namespace of its own and reports what
its request needs plus --extra other topics (a real robot has many it does not need), kept as
readers keep reports (KeptInterfaces: the payload's bytes, parsed again when drift asks). A round
replaces one robot's report (a new object, as a new payload is read into one) and a tenth of
the rounds make it drift. Medians and p90 over --rounds rounds.

    python bench/drift.py [--robots 10000] [--extra 200] [--rounds 51]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from robotconf.configurator.drift import DriftMemo, Need, drift_of, needs_of_rendered
from robotconf.configurator.render import render_fleet
from robotconf.configurator.rendered import RenderedRequest
from robotconf.configurator.workspace import check
from robotconf.contract.interfaces import Interface, KeptInterfaces, RobotInterfaces

ROOT = Path(__file__).resolve().parents[1]


def requests(robots: int) -> list[RenderedRequest]:
    checked = check(ROOT, None)
    assert checked.ok, checked.errors
    fleet = render_fleet(checked.repo)
    scenarios = [r.scenario_requests for r in fleet.requests.values()]
    return [
        scenarios[i % len(scenarios)].request(f"r{i:05d}", f"robot {i}", "0" * 40, f"/r{i:05d}")
        for i in range(robots)
    ]


def others(extra: int) -> list[Interface]:
    return [
        Interface(name=f"/sensors/s{n}/data", type="std_msgs/msg/Float32") for n in range(extra)
    ]


def report(
    needs: tuple[Need, ...], extra: list[Interface], drop: int = 0, at: float = 1.0
) -> KeptInterfaces:
    """What the robot reports: what it needs (but the first `drop`), and `extra` topics more,
    kept as the reconciler and `robotconf status` keep it: the payload's bytes."""
    kinds = {"topic": "topics", "service": "services", "action_client": "actions"}
    found: dict[str, list[Interface]] = {"topics": [], "services": [], "actions": []}
    for need in needs[drop:]:
        found[kinds[need.kind]].append(Interface(name=need.name, type=need.type))
    found["topics"] += extra
    model = RobotInterfaces(**found, source="ros2", at=at)
    return KeptInterfaces(model.model_dump_json().encode(), model)


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def p(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=10_000)
    parser.add_argument("--extra", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=51)
    args = parser.parse_args()

    started = time.perf_counter()
    fleet = requests(args.robots)
    needs = {r.robot_id: needs_of_rendered(r) for r in fleet}
    extra = others(args.extra)
    before = rss_mb()
    reports = {r.robot_id: report(needs[r.robot_id], extra) for r in fleet}
    held = rss_mb() - before
    payload = sum(len(k.payload) for k in reports.values()) / len(reports)
    digests = {r.robot_id: r.digest for r in fleet}
    print(
        f"{args.robots:,} robots, {args.extra} extra topics each: set up in "
        f"{time.perf_counter() - started:.1f} s; the reports held: {held:.0f} MB "
        f"(payloads of {payload / 1024:.1f} KB)"
    )

    memo = DriftMemo()

    def incremental() -> int:
        drifted = 0
        for robot_id, digest in digests.items():
            drifted += memo.get(robot_id, digest, needs[robot_id], reports[robot_id]).drifted
        return drifted

    def full() -> int:
        return sum(drift_of(r, needs[r], reports[r]).drifted for r in digests)

    incremental()  # fills the memo: the first pass is a full one
    robots = list(digests)
    changed, whole, alone = [], [], []
    for n in range(args.rounds):
        robot_id = robots[(n * 7919) % len(robots)]
        # A new report (read at another time): its content differs, so the memo cannot serve it.
        drop = 1 if n % 10 == 0 else 0
        reports[robot_id] = report(needs[robot_id], extra, drop, at=2.0 + n)
        before = memo.computed
        t0 = time.perf_counter()
        incremental()
        changed.append(time.perf_counter() - t0)
        assert memo.computed == before + 1, memo.computed - before  # that robot, no other
        t0 = time.perf_counter()
        drift_of(robot_id, needs[robot_id], reports[robot_id])
        alone.append(time.perf_counter() - t0)
        if n < 9:  # a full comparison is slow: fewer rounds of it
            t0 = time.perf_counter()
            full()
            whole.append(time.perf_counter() - t0)

    print(
        f"one robot's interfaces changed, the fleet judged incrementally: p50 "
        f"{statistics.median(changed) * 1e3:.2f} ms, p90 {p(changed, 0.9) * 1e3:.2f} ms "
        f"({args.rounds} rounds); that robot's drift alone p50 "
        f"{statistics.median(alone) * 1e3:.3f} ms"
    )
    print(
        f"full comparison of the fleet: p50 {statistics.median(whole) * 1e3:.0f} ms "
        f"({len(whole)} rounds): {statistics.median(whole) / statistics.median(changed):.0f}x"
    )


if __name__ == "__main__":
    main()
