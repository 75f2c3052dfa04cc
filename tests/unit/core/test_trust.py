"""The rule for files read as configuration or credentials (contract/trust.py), over the facts
alone: who owns the file, its mode and kind, its size."""

from __future__ import annotations

import stat

import pytest

from robotconf.contract.trust import FileFacts, Trust, folder_refusal, owner_trusted, refusal

ME, OTHER, ROOT = 1000, 1001, 0
REG = stat.S_IFREG
LIMIT = 1024


def judged(uid: int, mode: int, kind: Trust, size: int = 10) -> str | None:
    return refusal(FileFacts(uid=uid, mode=mode, size=size), ME, kind, "/etc/x", LIMIT)


@pytest.mark.parametrize("kind", list(Trust))
@pytest.mark.parametrize("uid", [ME, ROOT])
def test_a_private_file_of_the_user_or_root_is_trusted(uid: int, kind: Trust) -> None:
    assert judged(uid, REG | 0o600, kind) is None
    assert judged(uid, REG | 0o400, kind) is None


def test_configuration_may_be_read_by_others_a_secret_may_not() -> None:
    assert judged(ME, REG | 0o644, Trust.CONFIG) is None
    assert judged(ROOT, REG | 0o640, Trust.CONFIG) is None
    for mode in (0o640, 0o604, 0o644):
        reason = judged(ME, REG | mode, Trust.SECRET)
        assert reason == (
            f"may be read by others (mode {mode:04o}): chmod 600 /etc/x, as ssh asks of a key"
        )


@pytest.mark.parametrize("mode", [0o620, 0o602, 0o666, 0o777])
def test_a_file_others_may_change_is_refused(mode: int) -> None:
    assert judged(ME, REG | mode, Trust.CONFIG) == (
        f"may be changed by others (mode {mode:04o}): chmod go-w /etc/x"
    )
    assert judged(ROOT, REG | mode, Trust.SECRET) == (
        f"may be changed by others (mode {mode:04o}): chmod 600 /etc/x"
    )


@pytest.mark.parametrize("kind", list(Trust))
def test_a_file_of_another_user_is_refused_whatever_its_mode(kind: Trust) -> None:
    reason = judged(OTHER, REG | 0o600, kind)
    assert reason is not None and reason.startswith(
        f"belongs to user id {OTHER}, not to you (uid {ME}) or root"
    )


@pytest.mark.parametrize(
    ("mode", "said"),
    [
        (stat.S_IFLNK | 0o777, "a symbolic link"),
        (stat.S_IFIFO | 0o600, "a named pipe (FIFO)"),
        (stat.S_IFDIR | 0o700, "a folder"),
        (stat.S_IFCHR | 0o600, "a device"),
        (stat.S_IFSOCK | 0o600, "a socket"),
    ],
)
def test_only_a_regular_file_is_read(mode: int, said: str) -> None:
    assert judged(ME, mode, Trust.CONFIG) == (
        f"is {said}, not a regular file: put the file itself at /etc/x"
    )


def test_the_size_is_bounded_before_reading() -> None:
    assert judged(ME, REG | 0o600, Trust.SECRET, size=LIMIT) is None
    assert judged(ME, REG | 0o600, Trust.SECRET, size=LIMIT + 1) == (
        "is 1,025 bytes, over the limit of 1,024"
    )


def test_the_kind_is_judged_first_then_the_owner_then_the_mode() -> None:
    """One reason, the one to mend first: a link is not chmodded, another's file not owned."""
    assert "symbolic link" in (judged(OTHER, stat.S_IFLNK | 0o777, Trust.SECRET) or "")
    assert "belongs to" in (judged(OTHER, REG | 0o666, Trust.SECRET) or "")


def test_root_judges_by_the_same_rule() -> None:
    assert owner_trusted(ROOT, ROOT) and not owner_trusted(ME, ROOT)
    assert refusal(FileFacts(ME, REG | 0o600, 1), ROOT, Trust.SECRET, "/x", LIMIT) is not None


def test_a_folder_of_another_owner_is_not_walked_into() -> None:
    assert folder_refusal(ME, ME, "/home/me") is None
    assert folder_refusal(ROOT, ME, "/home") is None
    reason = folder_refusal(OTHER, ME, "/home/other")
    assert reason is not None and reason.startswith("/home/other belongs to user id 1001")
    assert "safe.directory" in reason
