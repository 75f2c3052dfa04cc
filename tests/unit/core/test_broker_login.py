"""The embedded broker's logins: one password file per user, and none left for robots that left
the fleet."""

from __future__ import annotations

from pathlib import Path

from robotconf.workstation.broker_login import (
    RECONCILER,
    USERNAME,
    accepts,
    broker_login,
    prune_logins,
)


def test_a_login_is_made_once_and_kept(tmp_path: Path) -> None:
    first = broker_login(tmp_path, "tb3-01")
    again = broker_login(tmp_path, "tb3-01")
    assert first.password() == again.password()
    assert (first.password_file.stat().st_mode & 0o777) == 0o600
    assert accepts(tmp_path, "tb3-01", first.password())
    assert not accepts(tmp_path, "tb3-02", first.password())


def test_pruning_removes_the_logins_of_robots_that_left(tmp_path: Path) -> None:
    for user in (USERNAME, RECONCILER, "tb3-01", "tb3-02", "tb3-03"):
        broker_login(tmp_path, user)
    password = broker_login(tmp_path, "tb3-02").password()
    (tmp_path / "notes.txt").write_text("not a login\n")

    gone = prune_logins(tmp_path, {USERNAME, RECONCILER, "tb3-01"})

    assert gone == ["tb3-02", "tb3-03"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "notes.txt",
        "operator.password",
        "reconciler.password",
        "tb3-01.password",
    ]
    assert not accepts(tmp_path, "tb3-02", password)
    assert prune_logins(tmp_path, {USERNAME, RECONCILER, "tb3-01"}) == []
