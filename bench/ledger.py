"""The outcome ledger's speed: SQLite alone, and the stream through a real broker into it.

1. `ledger`: N outcome records (10,000 robots, a few tasks, four outcomes) kept in batches of
   --batch (one transaction each, as the feed commits them), in a fresh ledger file: records
   per second, and a history query of the newest revision beside the one before.
2. `stream`: a real Mosquitto, the reconciler's feed (`reconciler/ledger_feed.py`: persistent
   session, QoS 1, acknowledged after each commit) and a publisher that sends --rate records a
   second for --seconds, spread over 10,000 robots' outcomes topics (one goal each 10 s at
   1,000/s). Falling behind shows as a backlog that grows: the records waiting for their
   commit are sampled every second, and the lag from publish to commit measured.

    python bench/ledger.py [--records 200000] [--batch 500] [--rate 1000] [--seconds 30]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import paho.mqtt.client as paho

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.contract.mqtt import Connection, make_client
from robotconf.contract.wire import Topics
from robotconf.readmodel.ledger import Ledger, ledger_path
from robotconf.reconciler.ledger_feed import LedgerFeed, LedgerSettings
from tests.support.mosquitto import Mosquitto

ROBOTS = 10_000
TASKS = ("Delivery", "Guide", "Patrol", "Dock")
OUTCOMES = (OutcomeState.SUCCEEDED,) * 7 + (OutcomeState.FAILED,) * 2 + (OutcomeState.CANCELED,)


def record(i: int, revision: str, now: float) -> OutcomeRecord:
    robot = f"tb3-{i % ROBOTS:05d}"
    outcome = OUTCOMES[i % len(OUTCOMES)]
    return OutcomeRecord(
        robot_id=robot,
        revision=revision,
        digest="sha256:" + "ab" * 32,
        scenario=f"scenario-{i % 20:02d}",
        run="r-1",
        seq=i // ROBOTS,
        goal=f"g{i}",
        task=TASKS[i % len(TASKS)],
        outcome=outcome,
        code="NAV2_TIMEOUT" if outcome is OutcomeState.FAILED else None,
        message="the path is blocked" if outcome is OutcomeState.FAILED else None,
        started_at=now - 8.0,
        ended_at=now,
        duration=8.0 + (i % 7),
    )


def bench_ledger(records: int, batch: int, folder: Path) -> None:
    path = ledger_path(folder / "alone")
    ledger = Ledger.open_or_start(path)
    now = time.time()
    made = [record(i, "a" * 40 if i < records // 2 else "b" * 40, now) for i in range(records)]
    started = time.perf_counter()
    for start in range(0, records, batch):
        ledger.add(made[start : start + batch], streak=3)
    took = time.perf_counter() - started
    size = path.stat().st_size + path.with_name(path.name + "-wal").stat().st_size
    print(
        f"ledger: {records:,} records in batches of {batch}: {took:.2f} s, "
        f"{records / took:,.0f} records/s ({size / records:.0f} bytes a record on disk)"
    )
    started = time.perf_counter()
    history = ledger.history()
    took = time.perf_counter() - started
    print(
        f"ledger: history of {history.report.revision[:12]} ({history.report.tally.total:,} "
        f"outcomes) beside the one before: {took:.2f} s"
    )
    ledger.close()


def bench_stream(rate: int, seconds: float, folder: Path) -> None:
    broker = Mosquitto(folder / "broker", extra_config=["max_queued_messages 100000"])
    broker.start()
    try:
        connection = Connection(url=broker.url)
        feed = LedgerFeed(connection, "bench", LedgerSettings(folder / "stream"))
        feed.start()
        time.sleep(1.0)  # subscribed
        topics = Topics("bench")
        publisher = make_client(connection, "bench-publisher")
        publisher.max_inflight_messages_set(0)
        publisher.max_queued_messages_set(0)
        publisher.connect(broker.host, broker.port)
        publisher.loop_start()
        samples: list[int] = []
        done = threading.Event()

        def sample() -> None:
            while not done.wait(1.0):
                samples.append(feed.pending)

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        total = int(rate * seconds)
        sent_at: dict[int, float] = {}
        started = time.monotonic()
        for i in range(total):
            due = started + i / rate
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            made = record(i, "c" * 40, time.time())
            sent_at[i] = time.monotonic()
            publisher.publish(
                topics.goal_outcomes(made.robot_id), made.model_dump_json().encode(), qos=1
            )
        published = time.monotonic() - started
        deadline = time.monotonic() + 60
        while feed.kept < total and time.monotonic() < deadline:
            time.sleep(0.05)
        drained = time.monotonic() - started
        done.set()
        print(
            f"stream: {total:,} records published in {published:.1f} s "
            f"({total / published:,.0f}/s), all {feed.kept:,} kept {drained - published:.2f} s "
            f"after the last was sent; refused {feed.refused}, duplicates {feed.duplicates}"
        )
        print(
            f"stream: records waiting for their commit, sampled each second: median "
            f"{statistics.median(samples or [0]):.0f}, max {max(samples or [0])}"
        )
        publisher.loop_stop()
        publisher.disconnect()
        feed.stop()
        with Ledger.open(ledger_path(folder / "stream"), read_only=True) as ledger:
            print(f"stream: the ledger holds {ledger.count():,} records")
    finally:
        broker.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, default=200_000)
    parser.add_argument("--batch", type=int, default=500)
    parser.add_argument("--rate", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--only", choices=("ledger", "stream"), default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.only in (None, "ledger"):
            bench_ledger(args.records, args.batch, Path(tmp))
        if args.only in (None, "stream"):
            bench_stream(args.rate, args.seconds, Path(tmp))


if __name__ == "__main__":
    paho.Client  # noqa: B018 - paho is what the publisher uses
    main()
