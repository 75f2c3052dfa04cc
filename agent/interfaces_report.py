"""The robot's interfaces topic: the probe read on the agent's loop, each changed report published.

The reading itself (the source run as a child, its output parsed and bounded) is
agent/interfaces.py's; this is what the agent does with it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping

from robotconf.agent.broker_link import BrokerLink
from robotconf.agent.config import AgentConfig
from robotconf.agent.interfaces import InterfaceProbe
from robotconf.agent.logs import Redactor

log = logging.getLogger("robotconf.agent")


class InterfacesReport:
    """One robot's interfaces: read when due, published when they change or the link is new;
    a reading's error goes into the status (`error`)."""

    def __init__(self, probe: InterfaceProbe, link: BrokerLink) -> None:
        self.probe = probe
        self.link = link

    @classmethod
    def of(
        cls,
        config: AgentConfig,
        env: Callable[[], Mapping[bytes, bytes]],
        redactor: Redactor,
        link: BrokerLink,
    ) -> InterfacesReport | None:
        """The report agent.yaml asks for (`interfaces:`), else None. `env`: the environment
        the source runs with, asked for at every reading."""
        if config.interfaces is None:
            return None
        probe = InterfaceProbe(
            config.interfaces,
            env,
            config.workdir,
            redact=lambda text: redactor.fresh().line(text),
        )
        return cls(probe, link)

    @property
    def error(self) -> str | None:
        return self.probe.error

    def watches(self) -> dict[int, object]:
        return self.probe.watches()

    def due(self) -> float:
        return self.probe.due()

    def read(self, ready: Iterable[int], now: float, connected: bool) -> bool:
        """One look at the source; True when its error (in the status) changed. A bug here is
        logged and the reading given up: it never stops the agent."""
        probe = self.probe
        before = probe.error
        try:
            report = probe.service(ready, now)
        except Exception:
            log.exception("internal error while reading the interfaces; trying again later")
            probe.postpone(now)
            return False
        if report is not None and connected:
            self.link.publish_interfaces(report.model_dump_json(exclude_none=True).encode("utf-8"))
        return probe.error != before

    def republish(self) -> None:
        """The last report again, for a new connection (the broker may have lost it)."""
        report = self.probe.report
        if report is not None:
            self.link.publish_interfaces(report.model_dump_json(exclude_none=True).encode("utf-8"))

    def close(self) -> None:
        self.probe.close()
