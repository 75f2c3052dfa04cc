"""Judging a wave's evidence at 10,000 robots: one step's count of the outcomes that arrived
since the step before, beside a full recount of the wave's window (`rollout.verify`).

A ledger file holds --records outcomes of 10,000 robots received over the wave's window, half
of them the wave's robots on the new digest, half the stable robots (the comparison side).
Then, --steps times, --per-step more outcomes arrive (one reconcile step's worth: 1,000 a
second at a 2 s poll is 2,000) and the step is timed two ways:

- incremental: `EvidenceCounter.count` (what the reconciler does): the rows after the last
  one counted, then the verdict;
- recount: a new counter over the whole window each step, then the verdict.

    python bench/wave_evidence.py [--records 500000] [--per-step 2000] [--steps 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robotconf.contract.goals import OutcomeRecord, OutcomeState
from robotconf.readmodel.ledger import Ledger, ledger_path
from robotconf.reconciler.evidence import EvidenceKey, Roles, WaveEvidence, judge, new_evidence
from robotconf.reconciler.evidence_feed import EvidenceCounter

ROBOTS = 10_000
NEW = "sha256:" + "ab" * 32
OLD = "sha256:" + "cd" * 32
OUTCOMES = (OutcomeState.SUCCEEDED,) * 9 + (OutcomeState.FAILED,)


def records(start: int, count: int, now: float) -> list[OutcomeRecord]:
    found = []
    for i in range(start, start + count):
        robot = i % ROBOTS
        found.append(
            OutcomeRecord(
                robot_id=f"tb3-{robot:05d}",
                revision="b" * 40 if robot < ROBOTS // 2 else "a" * 40,
                digest=NEW if robot < ROBOTS // 2 else OLD,
                scenario=f"scenario-{robot % 20:02d}",
                run="r-1",
                seq=i // ROBOTS,
                goal=f"g{i}",
                task="Delivery",
                outcome=OUTCOMES[i % len(OUTCOMES)],
                code="NAV2_TIMEOUT" if i % len(OUTCOMES) == 9 else None,
                ended_at=now,
            )
        )
    return found


def catch_up(counter: EvidenceCounter, evidence: WaveEvidence) -> None:
    """Counts until nothing is left (a step counts ROWS_PER_STEP at most)."""
    ledger = counter._open()
    assert ledger is not None
    while True:
        before = evidence.last_id
        counter._read(ledger, evidence)
        if evidence.last_id == before:
            return


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--records", type=int, default=500_000)
    parser.add_argument("--per-step", type=int, default=2_000)
    parser.add_argument("--steps", type=int, default=10)
    args = parser.parse_args()

    from robotconf.configurator.types import Verify

    verify = Verify(min_goals=1000, success_rate=0.8, compare="stable", timeout="1d")
    roles = Roles(
        new={f"tb3-{r:05d}": NEW for r in range(ROBOTS // 2)},
        stable={f"tb3-{r:05d}": OLD for r in range(ROBOTS // 2, ROBOTS)},
    )
    with tempfile.TemporaryDirectory() as folder:
        path = ledger_path(Path(folder))
        writer = Ledger.open_or_start(path)
        started = time.time() - 1
        key = EvidenceKey("b" * 40, 1, started)
        made = time.perf_counter()
        for at in range(0, args.records, 5000):
            writer.add(records(at, min(5000, args.records - at), time.time()))
        print(f"ledger: {args.records:,} outcomes in {time.perf_counter() - made:.1f} s")

        counter = EvidenceCounter(path)
        counter._evidence = new_evidence(key, roles, verify)  # the wave the rollout stands in
        first = time.perf_counter()
        evidence = counter._evidence
        catch_up(counter, evidence)
        print(f"first count of the window (a restart): {time.perf_counter() - first:.3f} s")

        incremental, recount = [], []
        next_id = args.records
        for _ in range(args.steps):
            writer.add(records(next_id, args.per_step, time.time()))
            next_id += args.per_step
            t = time.perf_counter()
            catch_up(counter, evidence)
            verdict = judge(verify, evidence, time.time())
            incremental.append(time.perf_counter() - t)
            t = time.perf_counter()
            fresh = new_evidence(key, roles, verify)
            catch_up(counter, fresh)
            again = judge(verify, fresh, time.time())
            recount.append(time.perf_counter() - t)
            assert (again.goals, again.verdict) == (verdict.goals, verdict.verdict)
        writer.close()
        counter.close()
    print(f"per step, {args.per_step:,} new outcomes, {args.steps} steps:")
    print(
        f"  incremental: median {statistics.median(incremental) * 1000:.1f} ms, "
        f"max {max(incremental) * 1000:.1f} ms"
    )
    print(
        f"  recount:     median {statistics.median(recount) * 1000:.1f} ms, "
        f"max {max(recount) * 1000:.1f} ms"
    )
    print(f"  verdict: {verdict.message}")


if __name__ == "__main__":
    main()
