"""A commit is read in one pass (one `git rev-parse`, one `git ls-tree`, one `git cat-file
--batch`, whatever the number of files), gives the work tree's verdict, and a damaged one is a
clean SourceError (issue 14, item 2)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from robotconf.configurator.source import FileTooLarge, GitSource, SourceError, WorkTreeSource
from robotconf.configurator.workspace import check
from robotconf.contract.yamlio import MAX_FILE_BYTES
from robotconf.reconciler.desired import load_desired
from tests.support.lab import Lab

SCENARIO = "configs/scenarios/delivery-gazebo.yaml"


@pytest.fixture
def lab(tmp_path: Path) -> Lab:
    lab = Lab(tmp_path / "lab")
    lab.commit("base")
    return lab


def _git_counter(tmp_path: Path) -> tuple[dict[str, str], Path]:
    """An environment whose `git` is the real one, each run noted (its arguments) in a log."""
    real = subprocess.run(["which", "git"], capture_output=True, text=True, check=True)
    shim = tmp_path / "bin"
    shim.mkdir()
    log = tmp_path / "git-runs.log"
    (shim / "git").write_text(f'#!/bin/sh\necho "$*" >> {log}\nexec {real.stdout.strip()} "$@"\n')
    (shim / "git").chmod(stat.S_IRWXU)
    return {**os.environ, "PATH": f"{shim}:{os.environ['PATH']}"}, log


def test_a_commit_is_read_by_a_fixed_number_of_git_processes(lab: Lab, tmp_path: Path) -> None:
    for i in range(200):
        lab.write(f"configs/scenarios/copy-{i:03d}.yaml", lab.read(SCENARIO))
    revision = lab.commit("200 more scenarios")
    env, log = _git_counter(tmp_path)
    code = (
        "import sys; from pathlib import Path; from robotconf.configurator.workspace import check\n"
        f"checked = check(Path({str(lab.root)!r}), {revision!r})\n"
        "print(checked.repo.files_read, len(checked.errors))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    files, errors = map(int, done.stdout.split())
    assert files > 200 and errors == 0
    runs = log.read_text().splitlines()
    assert [run.split()[0] for run in runs] == ["rev-parse", "ls-tree", "cat-file"]


def test_the_commit_and_the_work_tree_agree_on_every_file(lab: Lab) -> None:
    lab.write("configs/.hidden/x.yaml", "[not read\n")
    lab.write("models/actions/.draft.yaml", "[not read\n")
    lab.write("models/actions/README.md", "notes\n")
    lab.write("configs/scenarios/broken.yaml", "capability: [\n")
    lab.write("configs/scenarios/odd.yml", "capability: x\n")
    lab.path("models/tasks/Patrol.yaml").chmod(0o755)  # executable: still a file
    revision = lab.commit("odd files")
    work_tree, commit = WorkTreeSource(lab.root), GitSource(lab.root, revision)
    assert commit.files() == work_tree.files()
    assert commit.refused() == work_tree.refused() == {}
    assert dict(commit.read_each(commit.files())) == dict(work_tree.read_each(work_tree.files()))
    assert check(lab.root, revision).diagnostics == check(lab.root).diagnostics


def test_a_name_that_is_not_utf8_is_refused_in_a_commit_as_in_the_work_tree(lab: Lab) -> None:
    folder = os.fsencode(lab.path("configs/scenarios"))
    with open(folder + b"/caf\xe9.yaml", "wb") as handle:
        handle.write(b"capability: x\n")
    revision = lab.commit("a Latin-1 name")
    expected = {"configs/scenarios/caf\\xe9.yaml": "has a name that is not UTF-8; rename it"}
    assert GitSource(lab.root, revision).refused() == expected
    assert WorkTreeSource(lab.root).refused() == expected
    assert check(lab.root, revision).diagnostics == check(lab.root).diagnostics


def _git_in(folder: Path, *args: str) -> None:
    subprocess.run(
        ["git", "-c", "user.email=lab@example.org", "-c", "user.name=Lab", *args],
        cwd=folder,
        check=True,
        capture_output=True,
    )


def test_a_repository_in_a_subfolder_of_the_git_work_tree(tmp_path: Path) -> None:
    outer = tmp_path / "outer"
    outer.mkdir()
    _git_in(outer, "init", "-q", "-b", "main")
    (outer / "other.txt").write_text("before the lab\n")
    _git_in(outer, "add", "-A")
    _git_in(outer, "commit", "-qm", "no lab yet")
    lab = Lab(outer / "robots")
    _git_in(outer, "add", "-A")
    _git_in(outer, "commit", "-qm", "the lab")
    source = GitSource(lab.root, "HEAD")
    assert source.files() == WorkTreeSource(lab.root).files()
    assert load_desired(lab.root, "HEAD").ok
    with pytest.raises(SourceError, match="'HEAD~1' has no folder robots"):
        GitSource(lab.root, "HEAD~1")


def test_a_missing_object_is_a_clean_error(lab: Lab) -> None:
    lab.write("configs/scenarios/extra.yaml", lab.read(SCENARIO) + "# a blob of its own\n")
    revision = lab.commit("one more")
    blob = lab.git("rev-parse", f"{revision}:configs/scenarios/extra.yaml")
    (lab.root / ".git" / "objects" / blob[:2] / blob[2:]).unlink()  # a damaged clone
    with pytest.raises(SourceError, match=r"configs/scenarios/extra\.yaml .* is missing"):
        check(lab.root, revision)
    desired = load_desired(lab.root, revision)
    assert not desired.ok
    assert desired.problems[0].message.startswith(f"cannot read {revision}: ")
    done = lab.run("validate", "--rev", revision)
    assert done.returncode == 2 and done.stderr.count("\n") == 1
    assert "Traceback" not in done.stderr and "is missing" in done.stderr


def test_a_file_over_the_limit_in_a_commit_is_refused_unread_and_the_rest_read(lab: Lab) -> None:
    # git announces each blob's size before its content: the one over the limit is refused
    # there, and the files after it still come, each with its own bytes.
    big = "configs/scenarios/big.yaml"
    lab.path(big).write_bytes(b"#" * (MAX_FILE_BYTES + 1))
    revision = lab.commit("one file over the limit")
    source, work_tree = GitSource(lab.root, revision), WorkTreeSource(lab.root)
    paths = source.files()
    assert big in paths and paths[-1] != big and paths[0] != big
    read = dict(source.read_each(paths))
    expected = dict(work_tree.read_each(paths))
    refused = read.pop(big)
    assert isinstance(refused, FileTooLarge) and refused.size == MAX_FILE_BYTES + 1
    assert str(refused) == str(expected.pop(big))
    assert read == expected
    assert check(lab.root, revision).diagnostics == check(lab.root).diagnostics
