"""`robotconf up`'s desk file: found from below, trusted only while its `up` holds the lock, and
never stronger than the options or $ROBOTCONF_BROKER a user gives."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from workstation.cli.broker_options import BrokerOptions, desk_broker_options
from workstation.cli.options import repo_option
from workstation.up_desk import DESK_FILE, UpDesk, find_desk, remove_desk, write_desk


@pytest.fixture
def held_lock(tmp_path: Path) -> Iterator[Path]:
    """An up.lock held as `up` holds it (another open file: flock sees it as another holder)."""
    path = tmp_path / "work" / "up.lock"
    path.parent.mkdir()
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    try:
        yield path
    finally:
        os.close(fd)


def a_desk(lock: Path, tmp_path: Path) -> UpDesk:
    return UpDesk(
        broker="mqtt://127.0.0.1:40404",
        prefix="lab",
        pid=os.getpid(),
        lock=lock,
        username="operator",
        password_file=tmp_path / "operator.password",
        signing_key=tmp_path / "launch-signing.key",
    )


def test_a_running_up_s_desk_is_found_from_a_folder_below(held_lock: Path, tmp_path: Path) -> None:
    root = tmp_path / "lab"
    path = write_desk(root, a_desk(held_lock, tmp_path))
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    (root / "configs" / "scenarios").mkdir(parents=True)
    found, note = find_desk(root / "configs" / "scenarios")
    assert note is None and found == a_desk(held_lock, tmp_path)


def test_a_desk_whose_up_is_gone_is_stale(tmp_path: Path) -> None:
    lock = tmp_path / "up.lock"
    lock.write_text(f"{os.getpid()}\n")  # nobody holds it: its up died
    write_desk(tmp_path, a_desk(lock, tmp_path))
    found, note = find_desk(tmp_path)
    assert found is None and note is not None and "is stale" in note


def test_a_lock_held_by_another_up_is_not_this_desk_s(held_lock: Path, tmp_path: Path) -> None:
    desk = a_desk(held_lock, tmp_path)
    write_desk(tmp_path, UpDesk(**{**desk.__dict__, "pid": os.getpid() + 1}))
    found, note = find_desk(tmp_path)
    assert found is None and note is not None and "is stale" in note


def test_an_unreadable_desk_file_is_ignored_with_a_note(tmp_path: Path) -> None:
    (tmp_path / DESK_FILE).parent.mkdir(parents=True)
    (tmp_path / DESK_FILE).write_text("[1, 2")
    found, note = find_desk(tmp_path)
    assert found is None and note is not None and "is not robotconf up's desk file" in note


def test_up_removes_only_its_own_desk(held_lock: Path, tmp_path: Path) -> None:
    write_desk(tmp_path, a_desk(held_lock, tmp_path))
    remove_desk(tmp_path, os.getpid() + 1)
    assert (tmp_path / DESK_FILE).exists()
    remove_desk(tmp_path, os.getpid())
    assert not (tmp_path / DESK_FILE).exists()


@click.command()
@repo_option
@desk_broker_options
def shown(repo: Path, mqtt: BrokerOptions) -> None:
    print(mqtt.broker, mqtt.prefix, mqtt.username, mqtt.password_file, mqtt.signing_key)


def run(*argv: str, env: dict[str, str] | None = None) -> str:
    result = CliRunner().invoke(shown, list(argv), env=env or {"ROBOTCONF_BROKER": None})  # type: ignore[dict-item]
    assert result.exit_code == 0, result.output
    return result.output


def test_options_and_the_environment_win_over_the_desk(held_lock: Path, tmp_path: Path) -> None:
    desk = a_desk(held_lock, tmp_path)
    write_desk(tmp_path, desk)
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
