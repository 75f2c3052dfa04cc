"""The desired robots kept per revision: read back exactly as built, and anything else (another
revision, other code, a malformed or untrusted file) read as nothing, so the caller builds."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from types import MappingProxyType

import pytest

from robotconf.configurator.render import render_fleet
from robotconf.configurator.workspace import check
from robotconf.readmodel.verdicts import DesiredRobot, desired_from_fleet
from robotconf.workstation import desired_store
from tests.support.lab import ROOT

REV = "a" * 40


@pytest.fixture(scope="module")
def desired() -> dict[str, DesiredRobot]:
    robots = desired_from_fleet(render_fleet(check(ROOT).repo))
    assert any(robot.needs for robot in robots.values())  # the needs are exercised
    assert any(robot.labels for robot in robots.values())
    return robots


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    (tmp_path / ".git").mkdir()
    return tmp_path


def _same(found: dict[str, DesiredRobot] | None, want: dict[str, DesiredRobot]) -> None:
    assert found is not None
    assert list(found) == list(want)
    for robot_id, robot in want.items():
        kept = found[robot_id]
        assert tuple(kept.needs) == robot.needs
        assert (kept.scenario, kept.digest, kept.suspended, kept.template, kept.wave) == (
            robot.scenario,
            robot.digest,
            robot.suspended,
            robot.template,
            robot.wave,
        )
        assert dict(kept.labels) == dict(robot.labels)


def test_a_kept_revision_reads_back_as_built(repo: Path, desired: dict[str, DesiredRobot]) -> None:
    assert desired_store.read(repo, REV) is None
    desired_store.write(repo, REV, desired)
    entry = repo / ".git" / "robotconf" / "desired" / f"{REV}.json"
    assert entry.stat().st_mode & 0o777 == 0o600
    _same(desired_store.read(repo, REV), desired)
    assert desired_store.read(repo, "b" * 40) is None  # another revision: not kept


def test_an_entry_written_in_slices_is_one_whole_document(
    repo: Path, desired: dict[str, DesiredRobot]
) -> None:
    """More robots than one piece holds (and labels of any mapping type): the pieces make the
    document a single dump would, and it reads back robot by robot."""
    template = next(robot for robot in desired.values() if robot.needs and robot.labels)
    many = {
        f"r{n:05d}": dataclasses.replace(
            template, robot_id=f"r{n:05d}", labels=MappingProxyType({"n": str(n)})
        )
        for n in range(2 * desired_store._SLICE + 7)
    }
    data = desired_store.encode(REV, many)
    whole = json.loads(data)
    assert whole["robots"][0] == list(many)
    assert whole["robots"][5] == [{"n": str(n)} for n in range(len(many))]
    assert len(whole["robots"][7]) == len(many) and len(whole["needs"][0]) == len(template.needs)
    desired_store.write(repo, REV, many)
    _same(desired_store.read(repo, REV), many)


def test_an_entry_of_other_code_or_another_revision_is_nothing(
    desired: dict[str, DesiredRobot],
) -> None:
    data = desired_store.encode(REV, desired)
    _same(desired_store.decode(REV, data), desired)
    assert desired_store.decode("b" * 40, data) is None
    other = json.loads(data)
    other["stamp"] = "0" * 64
    assert desired_store.decode(REV, json.dumps(other).encode()) is None


def _broken(data: bytes) -> list[bytes]:
    """The entry broken one way at a time, each of which must read as nothing."""
    found = json.loads(data)
    out = [b"", b"[]", b"{", b"[" * 100_000, data[:-1]]
    for column, bad in [
        (("robots", 3), [1] * len(found["robots"][3])),  # suspended as ints
        (("robots", 0), [None] * len(found["robots"][0])),  # no robot ids
        (("robots", 5), [{"a": 1}] * len(found["robots"][5])),  # a label that is no text
        (("robots", 7), [[10**9]] * len(found["robots"][7])),  # a need out of range
        (("robots", 7), [[-1]] * len(found["robots"][7])),
        (("robots", 7), [[True]] * len(found["robots"][7])),  # a bool is no place
        (("needs", 1), found["needs"][1][:-1]),  # columns of different lengths
        (("needs", 4), [["x", 3]] * len(found["needs"][4])),
    ]:
        copy = json.loads(data)
        key, index = column
        copy[key][index] = bad
        out.append(json.dumps(copy).encode())
    missing = json.loads(data)
    del missing["needs"]
    out.append(json.dumps(missing).encode())
    return out


def test_a_malformed_entry_is_nothing(desired: dict[str, DesiredRobot]) -> None:
    for data in _broken(desired_store.encode(REV, desired)):
        assert desired_store.decode(REV, data) is None


def test_an_untrusted_file_is_not_read(repo: Path, desired: dict[str, DesiredRobot]) -> None:
    desired_store.write(repo, REV, desired)
    entry = repo / ".git" / "robotconf" / "desired" / f"{REV}.json"
    entry.chmod(0o620)  # writable by the group: anyone in it could plant an answer
    assert desired_store.read(repo, REV) is None
    entry.chmod(0o600)
    elsewhere = repo / "elsewhere.json"
    entry.rename(elsewhere)
    entry.symlink_to(elsewhere)  # a link: never followed
    assert desired_store.read(repo, REV) is None
    entry.unlink()
    assert desired_store.read(repo, "HEAD") is None  # only whole commit ids are keys
    desired_store.write(repo, "HEAD", desired)
    assert not (repo / ".git" / "robotconf" / "desired" / "HEAD.json").exists()


def test_nothing_is_kept_without_a_git_folder_of_ones_own(
    tmp_path: Path, desired: dict[str, DesiredRobot]
) -> None:
    desired_store.write(tmp_path, REV, desired)  # no .git at all
    assert not (tmp_path / ".git").exists()
    (tmp_path / ".git").write_text("gitdir: /elsewhere\n")  # a linked work tree's file
    desired_store.write(tmp_path, REV, desired)
    assert desired_store.read(tmp_path, REV) is None


def test_only_the_newest_entries_are_kept(repo: Path, desired: dict[str, DesiredRobot]) -> None:
    revisions = [f"{i:040x}" for i in range(desired_store.KEEP + 3)]
    for age, revision in enumerate(revisions):
        desired_store.write(repo, revision, desired)
        entry = repo / ".git" / "robotconf" / "desired" / f"{revision}.json"
        os.utime(entry, (1_000_000 + age, 1_000_000 + age))
    kept = sorted(p.stem for p in (repo / ".git" / "robotconf" / "desired").glob("*.json"))
    assert kept == sorted(revisions[-desired_store.KEEP :])


def test_a_half_entry_a_killed_writer_left_goes_and_a_fresh_one_stays(
    repo: Path, desired: dict[str, DesiredRobot]
) -> None:
    folder = repo / ".git" / "robotconf" / "desired"
    folder.mkdir(parents=True)
    left = folder / f".{REV}.4242.part"  # killed mid-write, long ago
    left.write_bytes(b'{"format": 1, "rev')
    old = 1_000_000.0
    os.utime(left, (old, old))
    writing = folder / f".{'c' * 40}.4343.part"  # another writer at it right now
    writing.write_bytes(b"{")
    desired_store.write(repo, "b" * 40, desired)
    assert not left.exists()
    assert writing.exists()
    _same(desired_store.read(repo, "b" * 40), desired)


def test_a_write_that_fails_leaves_no_half_entry(
    repo: Path, desired: dict[str, DesiredRobot]
) -> None:
    folder = repo / ".git" / "robotconf" / "desired"
    folder.mkdir(parents=True)
    (folder / f"{REV}.json").mkdir()  # the rename onto it fails: a folder is in the way
    desired_store.write(repo, REV, desired)  # no error: a cache that cannot keep, builds again
    assert list(folder.glob(".*.part")) == []
