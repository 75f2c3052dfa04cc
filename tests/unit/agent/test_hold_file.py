"""The brain's hold file as the agent looks at it: lstat only, never followed or read."""

from __future__ import annotations

import os
from pathlib import Path

from robotconf.agent.workdir import hold_exists, remove_hold


def test_anything_at_the_path_holds_and_nothing_is_followed(tmp_path: Path) -> None:
    hold = tmp_path / "brain.hold"
    assert not hold_exists(hold)
    hold.touch()
    assert hold_exists(hold)
    hold.unlink()
    hold.mkdir()
    assert hold_exists(hold)
    hold.rmdir()
    os.symlink(tmp_path / "nowhere", hold)  # dangling: still the brain's "not now"
    assert hold_exists(hold)
    assert not hold_exists(tmp_path / "a-file" / "below")  # under a file: nothing there


def test_a_stale_hold_of_any_kind_is_removed_but_never_a_symlinks_target(
    tmp_path: Path,
) -> None:
    target = tmp_path / "precious"
    target.write_text("keep")
    hold = tmp_path / "brain.hold"
    os.symlink(target, hold)
    assert remove_hold(hold) is None and not hold.is_symlink()
    assert target.read_text() == "keep"
    hold.mkdir()
    assert remove_hold(hold) is None and not hold.exists()
    # A tree the brain left (a stale hold of any kind): removed, never walked out of.
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "kept").write_text("keep")
    (hold / "deep" / "deeper").mkdir(parents=True)
    (hold / "deep" / "note").write_text("mine")
    os.symlink(outside, hold / "deep" / "link")
    assert remove_hold(hold) is None and not os.path.lexists(hold)
    assert (outside / "kept").read_text() == "keep"
    assert not hold_exists(hold)
    assert remove_hold(tmp_path / "absent") is None
