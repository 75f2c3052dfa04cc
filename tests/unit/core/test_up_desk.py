"""`robotconf up`'s desk file: found from below, trusted only while its `up` holds the lock on
that very file, only when it is the user's own, and never stronger than the options or
$ROBOTCONF_BROKER a user gives."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from robotconf.contract.trust import euid
from robotconf.workstation.cli.broker_options import BrokerOptions, desk_broker_options
from robotconf.workstation.cli.options import repo_option
from robotconf.workstation.up_desk import DESK_FILE, DeskLease, UpDesk, find_desk, write_desk


def a_desk(tmp_path: Path, pid: int | None = None) -> UpDesk:
    return UpDesk(
        broker="mqtt://127.0.0.1:40404",
        prefix="lab",
        pid=os.getpid() if pid is None else pid,
        username="operator",
        password_file=tmp_path / "operator.password",
        signing_key=tmp_path / "launch-signing.key",
    )


@pytest.fixture
def written(tmp_path: Path) -> Iterator[DeskLease]:
    """A desk file as a running `up` leaves it: written and locked by its lease."""
    lease = write_desk(tmp_path, a_desk(tmp_path))
    try:
        yield lease
    finally:
        lease.release()


def test_a_running_up_s_desk_is_found_from_a_folder_below(tmp_path: Path) -> None:
    root = tmp_path / "lab"
    lease = write_desk(root, a_desk(tmp_path))
    try:
        assert oct(lease.path.stat().st_mode & 0o777) == "0o600"
        (root / "configs" / "scenarios").mkdir(parents=True)
        found, note = find_desk(root / "configs" / "scenarios")
        assert note is None and found == a_desk(tmp_path)
    finally:
        lease.release()


def test_a_desk_whose_up_is_gone_is_stale(tmp_path: Path) -> None:
    write_desk(tmp_path, a_desk(tmp_path)).release()  # its up died: the kernel dropped the lock
    found, note = find_desk(tmp_path)
    assert found is None and note is not None and "is stale" in note


def test_a_lock_the_file_names_is_not_looked_at(tmp_path: Path, written: DeskLease) -> None:
    """Liveness is the lock on the file read, never a path or pid the file itself gives."""
    forged = tmp_path / "elsewhere" / DESK_FILE
    forged.parent.mkdir(parents=True)
    text = written.path.read_text().replace("{", '{"lock": "' + str(written.path) + '", ', 1)
    forged.write_text(text)
    forged.chmod(0o600)
    found, note = find_desk(tmp_path / "elsewhere")
    assert found is None and note is not None and "is stale" in note


def test_an_unreadable_desk_file_is_ignored_with_a_note(tmp_path: Path) -> None:
    (tmp_path / DESK_FILE).parent.mkdir(parents=True)
    (tmp_path / DESK_FILE).write_text("[1, 2")
    found, note = find_desk(tmp_path)
    assert found is None and note is not None and "is not robotconf up's desk file" in note


def test_up_removes_only_its_own_desk(tmp_path: Path) -> None:
    first = write_desk(tmp_path, a_desk(tmp_path))
    second = write_desk(tmp_path, a_desk(tmp_path, pid=os.getpid() + 1))  # another up's since
    first.remove()
    assert (tmp_path / DESK_FILE).exists()
    second.remove()
    assert not (tmp_path / DESK_FILE).exists()


def test_the_walk_up_stops_at_a_folder_of_another_owner(tmp_path: Path) -> None:
    """As git's safe.directory: a desk file above a folder someone else owns is never read
    (the owners are stood in at the one boundary, os.lstat's uid: tests cannot chown)."""
    lease = write_desk(tmp_path, a_desk(tmp_path))
    lab = tmp_path / "shared" / "lab"
    lab.mkdir(parents=True)
    other = euid() + 4242 if euid() else 4242

    def owner(folder: Path) -> int:
        return other if folder == tmp_path / "shared" else os.lstat(folder).st_uid

    try:
        assert find_desk(lab)[0] is not None  # with the real owners: found
        found, note = find_desk(lab, owner_of=owner)
        assert found is None and note is None  # nothing of ours there: silently not looked at
        found, note = find_desk(tmp_path / "shared", owner_of=owner)
        assert found is None and note is None
    finally:
        lease.release()


def test_a_desk_in_a_folder_of_another_owner_is_refused_with_a_note(tmp_path: Path) -> None:
    lease = write_desk(tmp_path, a_desk(tmp_path))
    other = euid() + 4242 if euid() else 4242
    try:
        found, note = find_desk(tmp_path, owner_of=lambda f: other if f == tmp_path else 0)
        assert found is None and note is not None
        assert f"belongs to user id {other}" in note and "safe.directory" in note
        up_folder = (tmp_path / DESK_FILE).parent
        found, note = find_desk(tmp_path, owner_of=lambda f: other if f == up_folder else euid())
        assert found is None and note is not None and str(up_folder) in note
    finally:
        lease.release()


@click.command()
@repo_option
@desk_broker_options
def shown(repo: Path, mqtt: BrokerOptions) -> None:
    print(mqtt.broker, mqtt.prefix, mqtt.username, mqtt.password_file, mqtt.signing_key)


def run(*argv: str, env: dict[str, str] | None = None) -> str:
    result = CliRunner().invoke(shown, list(argv), env=env or {"ROBOTCONF_BROKER": None})  # type: ignore[dict-item]
    assert result.exit_code == 0, result.output
    return result.output


def test_options_and_the_environment_win_over_the_desk(tmp_path: Path, written: DeskLease) -> None:
    desk = a_desk(tmp_path)
    repo = ["--repo", str(tmp_path)]
    assert run(*repo).split() == [
        desk.broker,
        "lab",
        "operator",
        str(desk.password_file),
        str(desk.signing_key),
    ]
    # Given a broker, only what is given: nothing of up's login or key goes to another broker.
    assert run(*repo, "--broker", "mqtt://elsewhere:1883").split() == [
        "mqtt://elsewhere:1883",
        "robotconf",
        "None",
        "None",
        "None",
    ]
    from_env = run(*repo, env={"ROBOTCONF_BROKER": "mqtt://env:1883"}).split()
    assert from_env[:3] == ["mqtt://env:1883", "robotconf", "None"]
    assert run(*repo, "--prefix", "mine", "--username", "me").split()[:3] == [
        desk.broker,
        "mine",
        "me",
    ]
