"""InterfaceProbe driven as the agent's loop drives it, with real child processes: output over
its bound, a program that cannot start, one that closes its output and lives on, secrets in a
reason, and a source that leaves a process behind without holding its output."""

from __future__ import annotations

import contextlib
import json
import os
import select
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from robotconf.agent.config import InterfacesConfig
from robotconf.agent.interfaces import MAX_OUTPUT, InterfaceProbe
from robotconf.agent.logs import Redactor
from robotconf.agent.process import is_alive
from robotconf.contract.interfaces import RobotInterfaces


def drive(probe: InterfaceProbe, deadline: float = 30.0) -> RobotInterfaces:
    """The loop's part: wait on the probe's pipes until its due time, then service it."""
    until = time.monotonic() + deadline
    while time.monotonic() < until:
        fds = list(probe.watches())
        wait = max(0.0, probe.due() - time.monotonic())
        ready: list[int] = []
        if fds:
            ready = select.select(fds, [], [], wait)[0]
        else:
            time.sleep(wait)
        report = probe.service(ready, time.monotonic())
        if report is not None:
            return report
    raise AssertionError("no report")


@pytest.fixture
def probes(tmp_path: Path) -> Iterator[list[InterfaceProbe]]:
    made: list[InterfaceProbe] = []
    yield made
    for probe in made:
        probe.close()


def probe_of(
    probes: list[InterfaceProbe], tmp_path: Path, command: list[str], **settings: object
) -> InterfaceProbe:
    config = InterfacesConfig.model_validate({"interval": 0.1, "command": command, **settings})
    env = {**os.environb, b"SECRET_TOKEN": b"s3cr3t-value-123"}
    redactor = Redactor(["s3cr3t-value-123"], ["SECRET_TOKEN"])
    probe = InterfaceProbe(config, lambda: env, tmp_path, lambda t: redactor.fresh().line(t))
    probes.append(probe)
    return probe


def test_output_over_its_bound_is_a_failure(probes: list[InterfaceProbe], tmp_path: Path) -> None:
    code = f"import sys; sys.stdout.write('x' * {MAX_OUTPUT + 10}); import time; time.sleep(30)"
    report = drive(probe_of(probes, tmp_path, [sys.executable, "-c", code]))
    assert report.error is not None and report.error.endswith(
        f"printed more than {MAX_OUTPUT:,} bytes"
    )
    assert probes[0].watches() == {}  # the child is gone, nothing left to wait on


def test_a_program_that_cannot_start(probes: list[InterfaceProbe], tmp_path: Path) -> None:
    report = drive(probe_of(probes, tmp_path, [str(tmp_path / "missing")]))
    assert report.error == f"cannot start '{tmp_path / 'missing'}': No such file or directory"


def test_a_program_that_closes_its_output_and_lives_on_is_timed_out(
    probes: list[InterfaceProbe], tmp_path: Path
) -> None:
    pid_file = tmp_path / "pid"
    script = f"echo $$ > {pid_file}; exec >&- 2>&-; sleep 60"
    report = drive(probe_of(probes, tmp_path, ["sh", "-c", script], timeout=1))
    assert report.error is not None and report.error.endswith("did not finish in 1 s")
    assert not is_alive(int(pid_file.read_text()))


def test_a_reason_never_carries_a_secret_of_the_environment(
    probes: list[InterfaceProbe], tmp_path: Path
) -> None:
    script = 'echo "login failed: token $SECRET_TOKEN" >&2; exit 3'
    report = drive(probe_of(probes, tmp_path, ["sh", "-c", script]))
    assert report.error is not None and "exited with code 3: login failed" in report.error
    assert "s3cr3t-value-123" not in report.error


def test_a_process_left_behind_without_the_output_does_not_hold_the_reading(
    probes: list[InterfaceProbe], tmp_path: Path
) -> None:
    """The reading ends with the command, and with its process group: what it left behind
    there dies with it (no process leaked per interval). A daemon that made a session of its
    own (ros2cli's `_ros2_daemon` since Humble: `setsid`) is no part of the reading and
    lives on."""
    grouped, detached = tmp_path / "grouped.pid", tmp_path / "detached.pid"
    listed = json.dumps({"topics": [{"name": "/scan", "type": "sensor_msgs/msg/LaserScan"}]})
    quiet = "</dev/null >/dev/null 2>&1"
    # The daemon names itself once it is in its own session (written then renamed, so whole),
    # and the reading ends only after: a kill of the group before setsid() ran would take it
    # too, which a loaded machine showed.
    daemon_script = f"echo $$ > {detached}.part && mv {detached}.part {detached}; exec sleep 60"
    script = (
        f"sleep 60 {quiet} & echo $! > {grouped}; "
        f"setsid sh -c '{daemon_script}' {quiet} & "
        f"while [ ! -e {detached} ]; do sleep 0.01; done; echo '{listed}'"
    )
    report = drive(probe_of(probes, tmp_path, ["sh", "-c", script]))
    left, daemon = int(grouped.read_text()), int(detached.read_text())
    try:
        assert report.error is None and [t.name for t in report.topics] == ["/scan"]
        deadline = time.monotonic() + 10  # SIGKILL sent: it is gone once scheduled
        while is_alive(left) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not is_alive(left)
        assert is_alive(daemon)
    finally:
        for pid in (left, daemon):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, 9)
