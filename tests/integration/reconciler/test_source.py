"""The git side: branch heads, ref watching, the remote cache clone, building from a commit."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from robotconf.configurator.source import SourceError
from robotconf.reconciler.desired import load_desired
from robotconf.reconciler.source import LocalBranch, RemoteBranch, redact
from tests.support.fleet import GitLab
from tests.support.watch import wait_for


def test_head_of_a_local_branch(lab: GitLab) -> None:
    assert LocalBranch(lab.root, "main").head() == lab.head()
    lab.git("pack-refs", "--all")  # the ref now lives only in packed-refs
    assert not (lab.root / ".git" / "refs" / "heads" / "main").exists()
    assert LocalBranch(lab.root, "main").head() == lab.head()


def test_unknown_branch_and_non_repository_are_clear_errors(lab: GitLab, tmp_path: Path) -> None:
    with pytest.raises(SourceError, match=r"branch 'mian' does not exist .*main"):
        LocalBranch(lab.root, "mian").head()
    (tmp_path / "plain").mkdir()
    with pytest.raises(SourceError, match="not a git repository"):
        LocalBranch(tmp_path / "plain", "main")


def test_a_new_commit_wakes_the_watcher(lab: GitLab) -> None:
    source = LocalBranch(lab.root, "main")
    woken = threading.Event()
    stop = threading.Event()
    try:
        assert source.watch(woken.set, stop)
        for attempt in range(3):  # the watcher needs a moment to register its inotify watches
            lab.replace("configs/fleet.yaml", "Guide bot", f"Guide bot {attempt}")
            head = lab.commit(f"rename {attempt}")
            if woken.wait(5):
                break
        assert woken.is_set()
        assert source.head() == head
    finally:
        stop.set()


def test_desired_state_comes_from_the_commit_not_the_work_tree(lab: GitLab) -> None:
    good = lab.head()
    lab.write("configs/fleet.yaml", "robots: {tb3-01: {scenario: nope}}\n")  # not committed
    desired = load_desired(lab.root, good)
    assert desired.ok and desired.fleet is not None
    assert sorted(desired.fleet.requests) == [
        "tb3-01",
        "tb3-02",
        "tb3-03",
        "tb3-04",
        "tb3-05",
        "tb3-07",
    ]

    bad = lab.commit("broken fleet")
    desired = load_desired(lab.root, bad)
    assert not desired.ok
    assert any(p.path == "configs/fleet.yaml" and "nope" in p.message for p in desired.problems)


def test_remote_branch_is_fetched_into_a_cache_clone(lab: GitLab, tmp_path: Path) -> None:
    source = RemoteBranch(str(lab.root), "main", tmp_path / "cache")
    source.refresh()
    assert source.head() == lab.head()
    assert load_desired(source.root, source.head()).ok

    lab.replace("configs/fleet.yaml", "Guide bot", "Guide")
    moved = lab.commit("rename")
    assert source.head() != moved  # only a fetch brings it
    source.refresh()
    assert wait_for(lambda: source.head() == moved, "the fetched head")

    gone = RemoteBranch(str(tmp_path / "nowhere"), "main", tmp_path / "cache")
    with pytest.raises(SourceError, match=r"fetching .* failed"):
        gone.refresh()


def test_credentials_never_appear_in_the_source_description() -> None:
    assert redact("https://bot:s3cret@git.example.org/lab.git") == "https://git.example.org/lab.git"
    assert redact("/srv/lab.git") == "/srv/lab.git"


def test_a_commit_with_a_trailing_newline_id_is_a_build_error_not_a_crash(lab: GitLab) -> None:
    lab.replace("configs/fleet.yaml", "tb3-01:", '"tb3-01\\n":')
    desired = load_desired(lab.root, lab.commit("newline id"))
    assert desired.fleet is None and desired.problems[0].code == "RC501"
