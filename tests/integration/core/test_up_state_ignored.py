"""`up`'s state folder ignores itself wherever it runs (a `.gitignore` of `*` inside it, as
virtualenvs do): in a lab's own repository, with no ignore rule of its own, `git add -A` after
an `up` commits none of its keys, passwords or tokens. Real git repositories; `prepare` is
what `up` runs before it writes anything."""

from __future__ import annotations

from pathlib import Path

from robotconf.workstation.up import prepare
from tests.support.fleet import GitLab


def _added(lab: GitLab) -> list[str]:
    lab.git("add", "-A")
    return lab.git("diff", "--cached", "--name-only").splitlines()


def test_git_add_all_after_up_commits_none_of_its_secrets(tmp_path: Path) -> None:
    lab = GitLab(tmp_path / "lab")
    setup = prepare(lab.root, None, None)
    state = lab.root / ".robotconf"
    assert (state / ".gitignore").read_text() == "*\n"
    # What up keeps there: its signing key, the broker's passwords, the UI token.
    for secret in ("up/keys/launch-signing.key", "up/broker/operator.password", "up/ui.token"):
        (state / secret).parent.mkdir(parents=True, exist_ok=True)
        (state / secret).write_text("secret\n")
    assert setup.workdir == state / "up"
    (lab.root / "notes.txt").write_text("a lab's own file\n")
    assert _added(lab) == ["notes.txt"]


def test_a_workdir_elsewhere_ignores_itself_too(tmp_path: Path) -> None:
    lab = GitLab(tmp_path / "lab")
    workdir = lab.root / "runs" / "today"
    prepare(lab.root, None, str(workdir))
    assert (workdir / ".gitignore").read_text() == "*\n"
    assert (lab.root / ".robotconf" / ".gitignore").read_text() == "*\n"  # desk.json's folder
    (workdir / "up.log").write_text("log\n")
    assert _added(lab) == []


def test_a_gitignore_of_the_lab_s_own_is_kept(tmp_path: Path) -> None:
    lab = GitLab(tmp_path / "lab")
    state = lab.root / ".robotconf"
    state.mkdir()
    mine = "# mine\n*\n!README\n"
    (state / ".gitignore").write_text(mine)
    prepare(lab.root, None, None)
    assert (state / ".gitignore").read_text() == mine  # it already ignores everything
    (state / ".gitignore").write_text("*.log")  # ignores only some: `*` is added, its line kept
    prepare(lab.root, None, None)
    assert (state / ".gitignore").read_text() == "*.log\n*\n"
    (state / "up").mkdir(exist_ok=True)
    (state / "up" / "ui.token").write_text("secret\n")
    assert _added(lab) == []
