"""`robotconf plan` without --base: against what the fleet's reconciler has applied (its retained
status on a real Mosquitto) when a broker answers, else against HEAD; the first line says which."""

from __future__ import annotations

import json
import subprocess

from robotconf.contract.wire import ReconcilerStatus, Topics
from tests.support.agents import publish
from tests.support.fleet import GitLab, robotconf_argv
from tests.support.mosquitto import Mosquitto, free_port

DELIVERY = "configs/scenarios/delivery-gazebo.yaml"


def plan(lab: GitLab, *args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        robotconf_argv("plan", "--repo", str(lab.root), *args),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    return done


def applied(url: str, revision: str | None) -> None:
    """The reconciler's retained status, as a reconciler that applied `revision` leaves it."""
    status = ReconcilerStatus(state="Ready", ready=True, last_applied_revision=revision)
    publish(url, Topics().reconciler_status, status.model_dump_json().encode())


def moved_on(lab: GitLab) -> tuple[str, str]:
    """The fleet runs the first commit; a second one changes tb3-01's scenario: HEAD."""
    running = lab.first
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.12")
    return running, lab.commit("faster")


def test_plan_compares_with_what_the_fleet_runs(lab: GitLab, mosquitto: Mosquitto) -> None:
    running, head = moved_on(lab)
    applied(mosquitto.url, running)
    done = plan(lab, "--broker", mosquitto.url)
    lines = done.stdout.splitlines()
    assert lines[0] == f"against what the fleet runs: {running[:12]} (applied by the reconciler)"
    assert done.returncode == 1 and "~ tb3-01" in done.stdout, done.stdout + done.stderr
    assert f'  {head[:12]} "faster"' in lines  # each side's commit, by its subject
    # The same change as --base names it; against HEAD there would be none.
    given = plan(lab, "--base", running, "--broker", mosquitto.url).stdout
    assert done.stdout.split("\n", 1)[1] == given
    assert plan(lab, "--base", "HEAD").returncode == 0

    as_json = json.loads(plan(lab, "--broker", mosquitto.url, "--format", "json").stdout)
    assert as_json["base"] == running and as_json["head"] == head
    assert as_json["subjects"][head] == "faster"
    assert as_json["against"] == {"source": "fleet", "why": "applied by the reconciler"}
    markdown = plan(lab, "--broker", mosquitto.url, "--format", "markdown").stdout
    assert markdown.startswith(f"against what the fleet runs: {running[:12]} ")
    # --rev: that commit instead of the work tree; the fleet's own revision changes nothing.
    same = plan(lab, "--broker", mosquitto.url, "--rev", running)
    assert same.returncode == 0 and same.stdout.startswith("against what the fleet runs:")


def test_plan_without_a_broker_compares_with_head(lab: GitLab) -> None:
    _, head = moved_on(lab)
    lab.replace(DELIVERY, "move_speed: 0.12", "move_speed: 0.13")  # the work tree moves on
    url = f"mqtt://127.0.0.1:{free_port()}"
    done = plan(lab, "--broker", url, "--wait", "600")  # refused at once: no wait
    lines = done.stdout.splitlines()
    assert lines[0] == f"against HEAD {head[:12]} (no broker reachable at {url})", done.stdout
    assert done.returncode == 1 and "~ tb3-01" in done.stdout
    as_json = json.loads(plan(lab, "--broker", url, "--format", "json").stdout)
    assert as_json["against"] == {"source": "HEAD", "why": f"no broker reachable at {url}"}


def test_a_broker_without_a_reconciler_status_means_head(lab: GitLab, mosquitto: Mosquitto) -> None:
    _, head = moved_on(lab)
    done = plan(lab, "--broker", mosquitto.url)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines()[0] == (
        f"against HEAD {head[:12]} (the broker at {mosquitto.url} holds no revision applied "
        "by a reconciler)"
    )


def test_a_fleet_revision_this_clone_lacks_says_fetch(lab: GitLab, mosquitto: Mosquitto) -> None:
    applied(mosquitto.url, "0123456789abcdef0123456789abcdef01234567")
    done = plan(lab, "--broker", mosquitto.url)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("robotconf: the fleet runs 0123456789ab,")
    assert lines[0].endswith("git fetch, or give --base"), lines[0]
