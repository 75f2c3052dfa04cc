"""Only regular files inside the repository are read, the work tree and a commit agree, and git's
edge cases are clean errors (issue 10, items 5–7)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from robotconf.configurator.source import GitSource, WorkTreeSource
from robotconf.contract.yamlio import MAX_FILE_BYTES
from robotconf.reconciler.desired import load_desired
from tests.support.lab import ROBOTCONF, Lab

CAPABILITY = "configs/capabilities/evil.yaml"


@pytest.fixture
def lab(tmp_path: Path) -> Lab:
    lab = Lab(tmp_path / "lab")
    lab.commit("base")
    return lab


def lines(lab: Lab, *args: str) -> tuple[int, list[str]]:
    done = lab.run("validate", *args)
    assert "Traceback" not in done.stderr + done.stdout
    return done.returncode, done.stdout.splitlines()


def test_a_link_to_a_file_outside_is_refused_and_never_read(lab: Lab, tmp_path: Path) -> None:
    secret = tmp_path / "secret.yaml"
    secret.write_text("SECRET-CONTENT: [unclosed\n")
    os.symlink(secret, lab.path(CAPABILITY))
    code, out = lines(lab)
    assert code == 1
    assert out == [
        f"{CAPABILITY}:1:1: error RC008 not read: {CAPABILITY} is a symbolic link; only regular "
        "files inside the repository are read: replace the link with the file itself"
    ]
    assert "SECRET" not in "\n".join(out)
    # Committed, git keeps it as a link: the reconciler gives the very same verdict.
    revision = lab.commit("a link")
    assert lines(lab, "--rev", revision) == (code, out)
    desired = load_desired(lab.root, revision)
    assert desired.fleet is None and [str(p) for p in desired.problems] == out


@pytest.mark.parametrize("target", ["/dev/zero", "/dev/null", "/dev/random"])
def test_a_link_to_a_device_is_refused(lab: Lab, target: str) -> None:
    os.symlink(target, lab.path(CAPABILITY))
    code, out = lines(lab)
    assert code == 1 and out[0].startswith(f"{CAPABILITY}:1:1: error RC008")


def test_a_fifo_is_refused_without_waiting_on_it(lab: Lab) -> None:
    os.mkfifo(lab.path(CAPABILITY))
    os.symlink(lab.path(CAPABILITY), lab.path("configs/scenarios/pipe.yaml"))
    code, out = lines(lab)  # lab.run's timeout guards against a hang
    assert code == 1
    assert "is a named pipe (FIFO), not a regular file" in out[0]
    assert "configs/scenarios/pipe.yaml:1:1: error RC008" in out[1]


def test_a_linked_folder_is_refused_not_followed(lab: Lab, tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "x.yaml").write_text("[broken\n")
    os.symlink(elsewhere, lab.path("configs/capabilities/more"))
    code, out = lines(lab)
    assert code == 1
    assert out == [
        "configs/capabilities/more:1:1: error RC008 not read: configs/capabilities/more is a "
        "symbolic link; only regular files inside the repository are read: replace the link "
        "with the file itself"
    ]
    assert lines(lab, "--rev", lab.commit("a linked folder")) == (code, out)


def test_a_file_over_the_limit_is_refused_by_its_size(lab: Lab) -> None:
    lab.path(CAPABILITY).write_bytes(b"#" * (MAX_FILE_BYTES + 1))
    code, out = lines(lab)
    assert code == 1 and len(out) == 1
    assert "RC008 file is 8,388,609 bytes, over the limit of 8,388,608" in out[0]
    assert lines(lab, "--rev", lab.commit("big")) == (code, out)


@pytest.mark.parametrize("name", ["x.yml", "x.YAML", "x.Yaml", "x.YML"])
def test_every_other_yaml_spelling_is_reported(lab: Lab, name: str) -> None:
    lab.write(f"configs/capabilities/{name}", "platform: ROS2\n")
    code, out = lines(lab)
    assert code == 1
    assert out[0].startswith(f"configs/capabilities/{name}:1:1: error RC105")


def test_validate_and_the_reconciler_agree_on_a_missing_fleet(lab: Lab) -> None:
    lab.remove("configs/fleet.yaml")
    code, out = lines(lab)
    assert code == 1 and len(out) == 1
    assert out[0].startswith("configs/fleet.yaml:1:1: error RC106 configs/fleet.yaml is missing")
    revision = lab.commit("no fleet")
    assert lines(lab, "--rev", revision) == (code, out)
    assert [str(p) for p in load_desired(lab.root, revision).problems] == out


def test_a_folder_that_is_not_a_configuration_repository(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    done = subprocess.run(
        [ROBOTCONF, "validate", "--repo", str(empty)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert "RC106" in done.stdout and "is it the repository root?" in done.stdout


def test_configs_as_a_file_is_the_same_error_in_a_commit(lab: Lab) -> None:
    lab.git("rm", "-rq", "configs")
    lab.path("configs").write_text("not a folder\n")
    code, out = lines(lab)
    assert code == 1
    assert out[0].startswith("configs:1:1: error RC008 not read: configs is a file")
    assert lines(lab, "--rev", lab.commit("configs is a file")) == (code, out)


def test_a_submodule_is_refused_in_the_work_tree_and_in_a_commit(lab: Lab, tmp_path: Path) -> None:
    other = Lab(tmp_path / "other")
    other.commit("other")
    lab.git(
        "-c",
        "protocol.file.allow=always",
        "submodule",
        "add",
        "-q",
        str(other.root),
        "models/vendor",
    )
    code, out = lines(lab)
    assert code == 1
    assert out[0].startswith(
        "models/vendor:1:1: error RC008 not read: models/vendor is a git submodule"
    )
    assert lines(lab, "--rev", lab.commit("a submodule")) == (code, out)


def test_deeply_nested_folders_are_walked_without_recursion(lab: Lab) -> None:
    folders = [lab.path("models")]
    for _ in range(1200):  # pathlib's mkdir(parents=True) itself recurses
        folders.append(folders[-1] / "d")
        folders[-1].mkdir()
    (folders[-1] / "x.yaml").write_text("a: 1\n")
    try:
        code, out = lines(lab)
        assert code == 1 and "RC105" in out[0]
    finally:  # shutil.rmtree (pytest's clean-up) recurses too
        (folders[-1] / "x.yaml").unlink()
        for folder in reversed(folders[1:]):
            folder.rmdir()


@pytest.mark.parametrize("rev", ["--output=/tmp/robotconf-pwned", "-h", "--all", "HEAD\n", ""])
def test_a_revision_that_looks_like_an_option_is_refused(lab: Lab, rev: str) -> None:
    done = lab.run("validate", f"--rev={rev}")
    assert done.returncode == 2, done
    assert "Traceback" not in done.stderr and done.stderr.count("\n") == 1
    assert not Path("/tmp/robotconf-pwned").exists()


def test_tags_and_objects_that_are_not_commits(lab: Lab) -> None:
    lab.git("tag", "-a", "-m", "release", "v1")
    assert lab.run("validate", "--rev", "v1").returncode == 0
    tree = lab.git("rev-parse", "HEAD^{tree}")
    lab.git("tag", "-a", "-m", "a tree", "tree-tag", tree)
    for rev in ("tree-tag", tree, "HEAD:configs", "HEAD..HEAD", "no-such"):
        done = lab.run("validate", "--rev", rev)
        assert done.returncode == 2 and "Traceback" not in done.stderr, (rev, done)
        assert "no such revision" in done.stderr


def test_a_shallow_clone_without_the_revision(lab: Lab, tmp_path: Path) -> None:
    first = lab.git("rev-parse", "HEAD")
    lab.replace("configs/fleet.yaml", "tb3-01", "tb3-91")
    lab.commit("second")
    shallow = tmp_path / "shallow"
    subprocess.run(
        ["git", "clone", "-q", "--depth", "1", f"file://{lab.root}", str(shallow)], check=True
    )
    done = subprocess.run(
        [ROBOTCONF, "validate", "--repo", str(shallow), "--rev", first],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "no such revision" in done.stderr
    assert load_desired(shallow, first).problems[0].message.startswith(f"cannot read {first}")


def test_the_rule_configuration_is_read_and_refused_alike_in_a_commit(lab: Lab) -> None:
    lab.write(".robotconf.yaml", "rules: {RC608: off}\n")
    revision = lab.commit("a rule configuration")
    work_tree, commit = WorkTreeSource(lab.root), GitSource(lab.root, revision)
    assert ".robotconf.yaml" in commit.files() and commit.files() == work_tree.files()
    assert commit.read(".robotconf.yaml") == work_tree.read(".robotconf.yaml")
    assert lab.check().repo.revision == revision  # the file counts for the work tree's revision
    lab.write(".robotconf.yaml", "rules: {RC608: warning}\n")
    assert lab.check().repo.revision == f"{revision}+dirty"
    lab.remove(".robotconf.yaml")
    os.symlink(lab.path("configs/fleet.yaml"), lab.path(".robotconf.yaml"))
    code, out = lines(lab)
    assert code == 1
    assert out == [
        ".robotconf.yaml:1:1: error RC008 not read: .robotconf.yaml is a symbolic link; only "
        "regular files inside the repository are read: replace the link with the file itself"
    ]
    assert lines(lab, "--rev", lab.commit("a linked rule configuration")) == (code, out)
    lab.remove(".robotconf.yaml")
    lab.write(".robotconf.yaml/rules.yaml", "rules: {}\n")
    code, out = lines(lab)
    assert code == 1 and out[0].startswith(".robotconf.yaml:1:1: error RC008 not read: ")
    assert "is a folder" in out[0]
    assert lines(lab, "--rev", lab.commit("a folder")) == (code, out)


def test_a_misspelt_rule_configuration_is_reported_not_ignored(lab: Lab) -> None:
    lab.write(".robotconf.yml", "rules: {RC608: off}\n")
    code, out = lines(lab)
    assert code == 1
    assert out == [
        ".robotconf.yml:1:1: error RC105 YAML files here end in .yaml; rename this .yml file "
        "(it is not read)"
    ]
    assert lines(lab, "--rev", lab.commit("a .yml rule configuration")) == (code, out)
