"""The desired robots of a revision are built once per repository and read back after: the
reconciler keeps the ones it serves, `robotconf status` keeps the ones it builds, and an entry
that cannot be read (or is gone) is built again with the same answer (issue 32 item 6)."""

from __future__ import annotations

import json
import signal
import subprocess
from dataclasses import replace
from pathlib import Path

from robotconf.workstation import desired_store
from tests.support.fleet import GitLab, Proc, robotconf_argv
from tests.support.mosquitto import Mosquitto
from tests.support.watch import FleetWatch, wait_for


def _status(lab: GitLab, mosquitto: Mosquitto) -> dict[str, object]:
    done = subprocess.run(
        robotconf_argv("status", "--repo", str(lab.root), "--broker", mosquitto.url, "--json"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert "Traceback" not in done.stderr and done.returncode in (0, 1), done.stderr
    found = json.loads(done.stdout)
    assert isinstance(found, dict)
    return found


def _rows(found: dict[str, object]) -> dict[str, tuple[object, ...]]:
    robots = found["robots"]
    assert isinstance(robots, list)
    return {
        r["robot_id"]: (r["verdict"], r["desired_digest"], r["scenario"], r["labels"])
        for r in robots
    }


def test_the_served_revision_is_kept_and_read_back(
    lab: GitLab, mosquitto: Mosquitto, tmp_path: Path
) -> None:
    kept = lab.root / ".git" / "robotconf" / "desired"
    reconciler = Proc(
        robotconf_argv(
            "reconcile", "--repo", str(lab.root), "--branch", "main", "--broker", mosquitto.url
        ),
        tmp_path / "reconciler.log",
    )
    watch = FleetWatch(mosquitto.url)
    try:
        head = lab.head()
        watch.wait_reconciler(lambda s: s.last_applied_revision == head, "head applied")
        entry = kept / f"{head}.json"
        wait_for(entry.exists, "the reconciler keeping its revision's robots")
        assert entry.stat().st_mode & 0o777 == 0o600
        from_entry = _status(lab, mosquitto)
        assert from_entry["desired_from"] == f"{lab.root} at {head[:12]}"

        # What status shows is the entry's (here one robot's request made up), not a build.
        robots = desired_store.decode(head, entry.read_bytes())
        assert robots is not None
        made_up = "sha256:" + "0" * 64
        robots["tb3-01"] = replace(robots["tb3-01"], digest=made_up)
        entry.write_bytes(desired_store.encode(head, robots))
        assert _rows(_status(lab, mosquitto))["tb3-01"][1] == made_up

        entry.unlink()  # built again, with the same answer, and kept again
        built = _status(lab, mosquitto)
        assert _rows(built) == _rows(from_entry) and len(_rows(built)) > 1
        assert entry.exists()

        entry.write_bytes(b'{"stamp": "broken')  # unreadable: built again, never an error
        assert _rows(_status(lab, mosquitto)) == _rows(from_entry)

        # A new revision: its own entry, and status compares with it, not with the kept one.
        fleet_yaml = lab.root / "configs" / "fleet.yaml"
        text = fleet_yaml.read_text()
        assert "namespace: tb3_02}" in text
        fleet_yaml.write_text(
            text.replace("namespace: tb3_02}", "namespace: tb3_02, suspended: true}")
        )
        new = lab.commit("suspend tb3-02")
        watch.wait_reconciler(lambda s: s.last_applied_revision == new, "the new head applied")
        wait_for((kept / f"{new}.json").exists, "the new revision kept")
        after = _status(lab, mosquitto)
        assert after["desired_from"] == f"{lab.root} at {new[:12]}"
        assert _rows(after)["tb3-02"][0] == "Suspended" != _rows(from_entry)["tb3-02"][0]
    finally:
        watch.close()
        assert reconciler.stop(signal.SIGTERM) == 0
        assert "Traceback" not in reconciler.output()
