"""broker-config's per-client queue: it holds every retained message of the fleet, twice over."""

from __future__ import annotations

from pathlib import Path

from robotconf.configurator.brokerconf import Listener, queued_messages, render_conf


def test_the_queue_holds_twice_the_fleet_s_retained_messages() -> None:
    # 5 retained topics per robot (goals among them) and 2 of the reconciler, twice, rounded up.
    assert queued_messages(10_000) == 101_000
    assert queued_messages(2_500) == 26_000
    # Never below 10,000: a small lab that grows is not caught out at Mosquitto's 1,000.
    assert queued_messages(0) == queued_messages(6) == 10_000


def test_the_generated_config_sets_it_and_says_why() -> None:
    conf = render_conf(Listener(), 8884, Path("/etc/robotconf"), 10_000)
    assert "\nmax_queued_messages 101000\n" in conf
    # Global, so before the first listener, and explained.
    assert conf.index("max_queued_messages") < conf.index("listener ")
    assert "QoS 0 included" in conf and "fleet of 10000 robot(s)" in conf
