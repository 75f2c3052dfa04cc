"""`reconcile --metrics HOST:PORT`: Prometheus metrics, written by the official client library
and served by the bounded edge (`readmodel/http_edge.py`).

A registry of our own (not the process-wide default), so that only robotconf_ metrics and the
ones that explain them are scraped.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import get_args

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    Info,
    generate_latest,
)
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector

from robotconf.configurator.drift import Drift
from robotconf.contract.goals import OutcomeRecord
from robotconf.contract.notes import VerdictNote
from robotconf.contract.wire import ReconcilerReason, RolloutStatus
from robotconf.contract.wire import Verdict as WaveVerdict
from robotconf.readmodel.http_edge import EdgeListener, Limits, Request, Response
from robotconf.readmodel.outcomes import MAX_LABEL_VALUES, NO_SCENARIO, OTHER, BoundedLabels
from robotconf.readmodel.verdicts import Verdict
from robotconf.reconciler.decide import state_of
from robotconf.reconciler.notify import OUTCOMES
from robotconf.reconciler.webhook import SERVERS, UNKNOWN, Outcome

INTERFACES_VERDICTS = ("reported", "unknown", "error")
LEDGER_RESULTS = ("kept", "duplicate", "refused")
WAVE_VERDICTS: tuple[str, ...] = get_args(WaveVerdict)  # Successful, Failed, Inconclusive
# Wave verdicts remembered as counted: a verdict noted again at each step of a pause (it is
# noted while the wave waits) is counted once; one older than this many is long past.
COUNTED = 64
# A scrape is a GET without a body, one or two Prometheus servers at a time; an idle connection
# costs only a file descriptor.
LIMITS = Limits(connections=64, per_client=8, head=5.0, silence=5.0, deadline=10.0)


class Metrics(EdgeListener):
    """The reconciler's metrics, and the HTTP server that serves them once `serve`d."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        r = self.registry
        self.duration = Histogram(
            "robotconf_reconcile_duration_seconds",
            "Duration of one reconcile step (observe, decide, apply, report)",
            registry=r,
            buckets=(0.01, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60),
        )
        self.applied = Info(
            "robotconf_applied_revision", "The revision applied last (serving)", registry=r
        )
        self.ready = Gauge("robotconf_ready", "1 when the branch's head is applied", registry=r)
        self.robots = Gauge(
            "robotconf_robots", "Robots per fleet status verdict", ["verdict"], registry=r
        )
        self.publishes = Counter(
            "robotconf_publishes",
            "Launch topic messages handed to the broker: requests published, topics cleared",
            ["action"],
            registry=r,
        )
        self.errors = Counter(
            "robotconf_reconcile_errors",
            "Reconcile steps that ended stalled, by reason",
            ["reason"],
            registry=r,
        )
        self.notifications = Counter(
            "robotconf_notifications",
            "Events per receiver: sent, failed (after retries) or dropped (queue full)",
            ["receiver", "outcome"],
            registry=r,
        )
        self.webhooks = Counter(
            "robotconf_webhooks",
            "Webhook requests (reconcile --webhook), by git server and outcome: fetch (a push "
            "of the branch, fetched at once), ignored (another branch or event), refused",
            ["server", "outcome"],
            registry=r,
        )
        self.drifted = Gauge(
            "robotconf_drifted_robots",
            "Assigned robots whose reported interfaces lack what their request needs (a "
            "missing interface or another type)",
            registry=r,
        )
        self.interfaces = Gauge(
            "robotconf_robot_interfaces",
            "Assigned robots by what they report of their interfaces: reported, unknown "
            "(nothing), error (the source failed, or the report cannot be read)",
            ["interfaces"],
            registry=r,
        )
        self._outcome_series()
        self._rollout_series()
        self._known_series()
        self._applied: str | None = None
        self._lock = threading.Lock()

    def _outcome_series(self) -> None:
        """What the outcome ledger counts (`reconciler/ledger_feed.py`)."""
        self.goal_outcomes = Counter(
            "robotconf_goal_outcomes",
            "Goal outcomes the robots reported, by scenario, task and outcome (the first "
            f"{MAX_LABEL_VALUES} scenarios and tasks seen by name, the rest as {OTHER!r}; no "
            "per-robot series)",
            ["scenario", "task", "outcome"],
            registry=self.registry,
        )
        self.ledger_records = Counter(
            "robotconf_ledger_records",
            "Outcome records the ledger took in: kept, duplicate (delivered again, kept once), "
            "refused (unreadable, too large, or naming another robot than its topic's)",
            ["result"],
            registry=self.registry,
        )
        self._scenarios = BoundedLabels(MAX_LABEL_VALUES)
        self._tasks = BoundedLabels(MAX_LABEL_VALUES)

    def _rollout_series(self) -> None:
        """What a rollout's verification shows (`rollout.verify`): verdicts, pauses, evidence."""
        self.wave_verdicts = Counter(
            "robotconf_rollout_verifications",
            "Wave verdicts of rollout.verify, each wave run's once: Successful, Failed, "
            "Inconclusive; dry_run true when the verification does not gate",
            ["verdict", "dry_run"],
            registry=self.registry,
        )
        self.paused = Gauge(
            "robotconf_rollout_paused",
            "1 while the rollout is Paused (rollout.paused, or a wave's evidence inconclusive)",
            registry=self.registry,
        )
        self._evidence = WaveEvidenceGauges()
        self.registry.register(self._evidence)
        self._counted: tuple[VerdictKey, ...] = ()
        self.stage_verified = Gauge(
            "robotconf_rollout_stage_verified",
            "1 when the revision rolled out is verified on the stage (fleet.yaml stages), "
            "else 0; the first 16 stages",
            ["stage"],
            registry=self.registry,
        )

    def _known_series(self) -> None:
        """Every series whose labels are known at start exists from the first scrape, at 0:
        `rate()` and `increase()` see the first error, and an alert needs no `absent()`."""
        for verdict in Verdict:
            self.robots.labels(verdict.value).set(0)
        for kind in INTERFACES_VERDICTS:
            self.interfaces.labels(kind).set(0)
        for action in ("publish", "clear"):
            self.publishes.labels(action)
        for result in LEDGER_RESULTS:
            self.ledger_records.labels(result)
        for wave_verdict in WAVE_VERDICTS:
            for dry_run in ("false", "true"):
                self.wave_verdicts.labels(wave_verdict, dry_run)
        for reason in ReconcilerReason:
            if state_of(reason) == "Stalled":
                self.errors.labels(reason.value)

    def receivers(self, names: list[str]) -> None:
        """--notify's receivers, each with its outcomes at 0 (told before they serve)."""
        for name in names:
            for outcome in OUTCOMES:
                self.notifications.labels(name, outcome)

    def webhook_servers(self) -> None:
        """--webhook's series at 0: each git server's outcomes, and the refusals of requests
        from no known server (the only outcome they can have)."""
        for server in SERVERS:
            for outcome in Outcome:
                self.webhooks.labels(server.name, outcome.value)
        self.webhooks.labels(UNKNOWN, Outcome.REFUSED.value)

    def serve(self, host: str, port: int, limits: Limits = LIMITS) -> None:
        """Listens now (OSError when it cannot) and serves on a thread of its own."""
        self._listen("metrics", _Scrapes(self.registry), limits, host, port)

    def step(
        self,
        seconds: float,
        *,
        applied: str | None,
        ready: bool,
        published: int,
        cleared: int,
        error: str | None,
    ) -> None:
        self.duration.observe(seconds)
        self.ready.set(1 if ready else 0)
        if published:
            self.publishes.labels("publish").inc(published)
        if cleared:
            self.publishes.labels("clear").inc(cleared)
        if error is not None:
            self.errors.labels(error).inc()
        with self._lock:
            if applied is not None and applied != self._applied:
                self._applied = applied
                self.applied.info({"revision": applied})

    def verdicts(self, counts: Mapping[Verdict, int]) -> None:
        for verdict in Verdict:
            self.robots.labels(verdict.value).set(counts.get(verdict, 0))

    def drift(self, drifts: Mapping[str, Drift]) -> None:
        """The assigned robots' drift: how many drifted, and what each reports."""
        counts = dict.fromkeys(INTERFACES_VERDICTS, 0)
        for found in drifts.values():
            counts[found.interfaces] += 1
        for kind, count in counts.items():
            self.interfaces.labels(kind).set(count)
        self.drifted.set(sum(1 for found in drifts.values() if found.drifted))

    def notified(self, receiver: str, outcome: str) -> None:
        self.notifications.labels(receiver, outcome).inc()

    def outcomes(self, records: Iterable[OutcomeRecord]) -> None:
        """Counts goal outcomes kept by the ledger, labels bounded (`BoundedLabels`)."""
        for record in records:
            self.goal_outcomes.labels(
                self._scenarios.label(record.scenario or NO_SCENARIO),
                self._tasks.label(record.task),
                record.outcome.value,
            ).inc()

    def ledger(self, kept: int, duplicates: int, refused: int) -> None:
        for result, count in zip(LEDGER_RESULTS, (kept, duplicates, refused), strict=True):
            if count:
                self.ledger_records.labels(result).inc(count)

    def webhook(self, server: str, outcome: str) -> None:
        self.webhooks.labels(server, outcome).inc()

    def rollout(self, rollout: RolloutStatus | None, reached: Sequence[VerdictNote]) -> None:
        """A step's rollout: its state and current wave's evidence, and the verdicts reached.
        Called from the reconcile loop only (one step at a time): `_counted` needs no lock."""
        self._counted, fresh = count_verdicts(self._counted, reached)
        for key in fresh:
            self.wave_verdicts.labels(key.verdict, "true" if key.dry_run else "false").inc()
        shown = RolloutGauges.of(rollout)
        self.paused.set(shown.paused)
        self._evidence.shown = shown
        for stage in (rollout.stages if rollout is not None else [])[:MAX_STAGES]:
            self.stage_verified.labels(stage.name).set(1 if stage.state == "verified" else 0)


MAX_STAGES = 16  # stage labels kept: a ladder is a few rungs, a label set stays bounded


@dataclass(frozen=True)
class VerdictKey:
    """A wave run's verdict, as counted: a run is (revision, wave, when it was published)."""

    revision: str
    wave: int | None
    started_at: float | None
    verdict: str
    dry_run: bool


def count_verdicts(
    counted: tuple[VerdictKey, ...], reached: Sequence[VerdictNote]
) -> tuple[tuple[VerdictKey, ...], list[VerdictKey]]:
    """The verdicts of `reached` not counted yet, and the memory after counting them (the last
    COUNTED). A step notes a paused wave's verdict again at each look, and an operator's resume
    notes it once more with their name: each is one wave verdict, counted once."""
    fresh: list[VerdictKey] = []
    for note in reached:
        if note.kind != "verification" or note.verdict is None:
            continue  # a resume of evidence still gathering is a decision, not a verdict
        key = VerdictKey(note.revision, note.wave, note.started_at, note.verdict, note.dry_run)
        if key in counted or key in fresh:
            continue
        fresh.append(key)
    return (*counted, *fresh)[-COUNTED:], fresh


@dataclass(frozen=True)
class RolloutGauges:
    """The gauges of a rollout's current wave. No evidence (no rollout, no verification, no
    rate yet) is no series rather than a 0 or a NaN: an alert on a low rate then fires on
    evidence only, never on its absence."""

    paused: int = 0
    goals: int | None = None
    rate: float | None = None

    @classmethod
    def of(cls, rollout: RolloutStatus | None) -> RolloutGauges:
        if rollout is None:
            return cls()
        paused = 1 if rollout.state == "Paused" else 0
        found = rollout.verification
        if found is None:
            return cls(paused)
        return cls(paused, found.goals, found.rate)


class WaveEvidenceGauges(Collector):
    """robotconf_rollout_wave_goals and robotconf_rollout_wave_success_rate, each only while
    there is a value to show (a `Gauge` would show 0 before any evidence, and keep showing the
    last wave's after the rollout ends). No labels: one current wave at a time."""

    GOALS = "robotconf_rollout_wave_goals"
    RATE = "robotconf_rollout_wave_success_rate"

    def __init__(self) -> None:
        self.shown = RolloutGauges()  # replaced whole by the reconcile loop: a scrape reads one

    def describe(self) -> Iterable[GaugeMetricFamily]:
        return [self._goals(None), self._rate(None)]

    def collect(self) -> Iterator[GaugeMetricFamily]:
        shown = self.shown
        if shown.goals is not None:
            yield self._goals(shown.goals)
        if shown.rate is not None:
            yield self._rate(shown.rate)

    def _goals(self, value: int | None) -> GaugeMetricFamily:
        return GaugeMetricFamily(
            self.GOALS,
            "Goals the current wave's robots ended on the revision (rollout.verify), while a "
            "wave is verified",
            value=value,
        )

    def _rate(self, value: float | None) -> GaugeMetricFamily:
        return GaugeMetricFamily(
            self.RATE,
            "The current wave's goal success rate, succeeded / (succeeded + failed), once it "
            "has decided goals",
            value=value,
        )


class _Scrapes:
    """The metrics listener's service: any path, GET or HEAD, as Prometheus exporters do."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.registry = registry

    def answer(self, request: Request) -> Response:
        if request.method not in ("GET", "HEAD"):
            return Response.text(405, "GET or HEAD only", ("Allow", "GET, HEAD"))
        return Response(200, generate_latest(self.registry), CONTENT_TYPE_LATEST)

    def refused(self, request: Request, code: int, message: str) -> Response:
        return Response.text(code, message)  # no method of a scrape has a body read
