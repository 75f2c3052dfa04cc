"""What the goals summaries add to `status` and the browser view's reading of the fleet, pure.

10,000 robots, each with a retained agent status; the same fleet again with a full goals summary
each (3 tasks, a goal underway, 10 recent outcomes, 5 vitals, 3 events: about 3 KB, a busy
robot's). Timed, median of --rounds, on one core:

  cold      every payload read (parse_retained, as `robotconf status` does once) and the rows
            made (build_rows)
  one       a step after one robot's summary changed (a progress update), with the read memo
            (`status --watch`, `up`): one payload read again, the rows made again
  json      the rows as `status --json` writes them
  page      the fleet page's success-rate box over every robot (the browser view, per change)

    python bench/goals_status.py [--robots 10000] [--rounds 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robotconf.contract.goals import CurrentGoal  # noqa: E402
from robotconf.contract.wire import AgentState, AgentStatus, Topics  # noqa: E402
from robotconf.readmodel.observed import ReadMemo, parse_retained  # noqa: E402
from robotconf.readmodel.verdicts import DesiredRobot, FleetStatus, build_rows  # noqa: E402
from robotconf.workstation.ui.goals_html import rates_box  # noqa: E402
from robotconf.workstation.ui.model import FleetQuery, Snapshot  # noqa: E402
from tests.support.goals_summaries import AT, ended, summary  # noqa: E402

T = Topics()
DIGEST = "sha256:" + "a" * 64


def fleet(robots: int, goals: bool) -> dict[str, bytes]:
    messages: dict[str, bytes] = {}
    for n in range(robots):
        robot = f"r{n:05}"
        status = AgentStatus(robot_id=robot, state=AgentState.RUNNING, digest=DIGEST)
        messages[T.status(robot)] = status.model_dump_json().encode()
        if goals:
            found = summary(
                robot,
                recent=[ended(f"g-{i}", task=f"Task{i % 3}", at=AT + i) for i in range(10)],
                vitals={"battery": 0.8, "cpu": 12.5, "pose": "x=1 y=2", "docked": False, "rate": 9},
                events=summary(robot).events * 3,
            )
            messages[T.goals(robot)] = found.model_dump_json().encode()
    return messages


def timed(work: Callable[[], object], rounds: int) -> float:
    times = []
    for _ in range(rounds):
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def measure(robots: int, rounds: int, goals: bool) -> dict[str, float]:
    messages = fleet(robots, goals)
    desired = {
        f"r{n:05}": DesiredRobot(f"r{n:05}", "delivery-gazebo", DIGEST) for n in range(robots)
    }
    cold = timed(lambda: build_rows(desired, parse_retained(messages, T)), rounds)
    memo = ReadMemo()
    build_rows(desired, parse_retained(messages, T, memo=memo))
    steps = iter(range(10**9))

    def one() -> None:
        step = next(steps)
        if goals:
            current = CurrentGoal(
                goal="g", task="Task0", started_at=AT, updated_at=AT + step, fraction=0.5
            )
            payload = summary("r00000", current=current).model_dump_json().encode()
            messages[T.goals("r00000")] = payload
        build_rows(desired, parse_retained(messages, T, memo=memo))

    one_step = timed(one, rounds)
    rows = build_rows(desired, parse_retained(messages, T))
    status = FleetStatus(rows, None, "bench")
    as_json = timed(status.as_json, rounds)
    snap = Snapshot(1, status, "mqtt://bench", True, None, AT, {}, {r.robot_id: r for r in rows})
    page = timed(lambda: rates_box(snap, FleetQuery()), rounds)
    return {"cold": cold, "one": one_step, "json": as_json, "page": page}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=10_000)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    without = measure(args.robots, args.rounds, goals=False)
    with_goals = measure(args.robots, args.rounds, goals=True)
    print(f"{args.robots:,} robots, median of {args.rounds} (seconds)")
    print(f"{'':8}{'statuses only':>16}{'with summaries':>16}")
    for name in without:
        print(f"{name:8}{without[name]:16.4f}{with_goals[name]:16.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
