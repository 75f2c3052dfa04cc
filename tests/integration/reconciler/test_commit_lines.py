"""Every revision is a commit, on real processes: the reconciler's status carries the subject,
author and time of the commits it names, read from the repository it follows, and `robotconf
status` shows the applied and the refused revision with their subjects."""

from __future__ import annotations

from tests.integration.reconciler.conftest import Fleet


def test_the_status_names_the_applied_and_the_refused_commit(fleet: Fleet) -> None:
    fleet.lab.replace("configs/fleet.yaml", "name: Lab patrol", "name: Lab patrol v2")
    good = fleet.lab.commit("Rename the lab patrol <b>now</b>")
    status = fleet.watch.wait_reconciler(
        lambda s: s.last_applied_revision == good and s.commit(good) is not None,
        "the applied commit described",
    )
    line = status.commit(good)
    assert line is not None and line.subject == "Rename the lab patrol <b>now</b>"
    assert line.author == "Lab" and line.at is not None
    fleet.lab.write("configs/fleet.yaml", "robots: [\n")
    bad = fleet.lab.commit("Break fleet.yaml")
    fleet.watch.wait_reconciler(
        lambda s: s.failed_revision == bad and s.commit(bad) is not None, "the refused commit"
    )
    text = fleet.status_cli().stdout
    assert f'applied {good[:12]} "Rename the lab patrol <b>now</b>"' in text
    assert f'attempted {bad[:12]} "Break fleet.yaml"' in text
