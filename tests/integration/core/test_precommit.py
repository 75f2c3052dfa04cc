"""The published pre-commit hooks, run by the real `pre-commit` in a throw-away git repository.

The hook definitions come from our `.pre-commit-hooks.yaml`; each becomes a `repo: local` hook
with `language: system` (the robotconf of this virtualenv), so nothing is fetched or built while
the id, entry, `files` and `pass_filenames` under test are exactly the published ones.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.support.install import clean_env, fresh_install, shared_wheel
from tests.support.lab import ROOT, Lab

BIN = Path(sys.executable).parent
PRE_COMMIT = str(BIN / "pre-commit")
FLEET = "configs/fleet.yaml"
GOOD = "tb3-02: {scenario: guide-gazebo,"
TYPO = "tb3-02: {scenaro: guide-gazebo,"


def _published_hooks() -> list[dict[str, Any]]:
    hooks: list[dict[str, Any]] = yaml.safe_load(
        (ROOT / ".pre-commit-hooks.yaml").read_text(encoding="utf-8")
    )
    return hooks


class FleetRepo:
    """A configuration repository (the example lab) under git, using our published hooks."""

    def __init__(self, tmp: Path) -> None:
        self.lab = Lab(tmp / "fleet")
        self.root = self.lab.root
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}
        self.env.update(
            HOME=str(tmp / "home"),
            PRE_COMMIT_HOME=str(tmp / "pre-commit-cache"),
            XDG_CACHE_HOME=str(tmp / "cache"),
            PATH=f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}",
        )
        (tmp / "home").mkdir()
        self.git("init", "-q", "-b", "main")
        # `system` installs nothing, so it takes no additional_dependencies: this venv has them.
        hooks = [
            {k: v for k, v in hook.items() if k != "additional_dependencies"}
            | {"language": "system"}
            for hook in _published_hooks()
        ]
        config = {"repos": [{"repo": "local", "hooks": hooks}]}
        (self.root / ".pre-commit-config.yaml").write_text(
            yaml.safe_dump(config, sort_keys=False), encoding="utf-8"
        )

    def git(self, *args: str) -> None:
        subprocess.run(["git", *args], cwd=self.root, env=self.env, check=True, capture_output=True)

    def robotconf(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(BIN / "robotconf"), *args, "--repo", str(self.root)],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=120,
        )

    def pre_commit(self, *args: str) -> subprocess.CompletedProcess[str]:
        self.git("add", "-A")
        return subprocess.run(
            [PRE_COMMIT, "run", "--color", "never", *args],
            cwd=self.root,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=300,
        )


@pytest.fixture
def repo(tmp_path: Path) -> FleetRepo:
    fleet = FleetRepo(tmp_path)
    assert fleet.robotconf("schemas").returncode == 0  # the schemas hook needs schemas/
    return fleet


def _status(output: str, name: str) -> str:
    """`Passed`, `Failed` or `Skipped` for the hook called `name` in pre-commit's report."""
    for line in output.splitlines():
        if line.startswith(name + "."):
            return line.rsplit(".", 1)[-1].split(")")[-1]
    raise AssertionError(f"hook {name!r} not in the output:\n{output}")


def test_broken_configuration_fails_with_the_located_message_then_passes(
    repo: FleetRepo,
) -> None:
    repo.lab.replace(FLEET, GOOD, TYPO)
    line = repo.lab.line_of(FLEET, TYPO)
    col = repo.lab.read(FLEET).splitlines()[line - 1].index("scenaro") + 1

    done = repo.pre_commit("--all-files")
    output = done.stdout + done.stderr
    assert done.returncode == 1, output
    assert _status(output, "robotconf validate") == "Failed"
    assert _status(output, "robotconf schemas --check") == "Passed"
    assert f"{FLEET}:{line}:{col}: error RC101 unknown field 'scenaro'" in output
    assert "did you mean 'scenario'?" in output
    assert "Traceback" not in output

    repo.lab.replace(FLEET, TYPO, GOOD)
    done = repo.pre_commit("--all-files")
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert _status(output, "robotconf validate") == "Passed"
    assert _status(output, "robotconf schemas --check") == "Passed"


def test_broken_yaml_fails_with_the_located_message(repo: FleetRepo) -> None:
    repo.lab.write("models/tasks/Tour.yaml", "implementations:\n\t- [NavigateToLocation]\n")
    done = repo.pre_commit("--all-files")
    output = done.stdout + done.stderr
    assert done.returncode == 1, output
    assert "models/tasks/Tour.yaml:2:1: error RC002 tab character in indentation" in output


def test_stale_schemas_fail_the_schemas_hook(repo: FleetRepo) -> None:
    repo.lab.write(
        "models/tasks/Tour.yaml",
        "description: Visit every location.\nimplementations: [[NavigateToLocation]]\n",
    )
    done = repo.pre_commit("--all-files")
    output = done.stdout + done.stderr
    assert done.returncode == 1, output
    assert _status(output, "robotconf validate") == "Passed"
    assert _status(output, "robotconf schemas --check") == "Failed"
    assert "schemas/ is stale" in output


def test_hooks_only_run_for_configuration_changes(repo: FleetRepo) -> None:
    repo.lab.replace(FLEET, GOOD, TYPO)  # broken, but not among the files of this run
    (repo.root / "README.md").write_text("# our fleet\n", encoding="utf-8")
    done = repo.pre_commit("--files", "README.md")
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert _status(output, "robotconf validate") == "Skipped"
    assert _status(output, "robotconf schemas --check") == "Skipped"
    # whole-repository: one file of configs/ is enough to check them all
    done = repo.pre_commit("--files", "models/tasks/Patrol.yaml")
    assert done.returncode == 1
    assert f"{FLEET}:" in done.stdout + done.stderr


def test_a_change_of_the_rule_configuration_alone_runs_validate(repo: FleetRepo) -> None:
    (repo.root / ".robotconf.yaml").write_text("rules: {RC501: off}\n", encoding="utf-8")
    done = repo.pre_commit("--files", ".robotconf.yaml")
    output = done.stdout + done.stderr
    assert done.returncode == 1, output
    assert _status(output, "robotconf validate") == "Failed"
    assert ".robotconf.yaml:1:9: error RC801 RC501 cannot be tuned" in output


def test_this_repositorys_own_hooks_mirror_the_published_ones() -> None:
    own = yaml.safe_load((ROOT / ".pre-commit-config.yaml").read_text(encoding="utf-8"))
    local = {h["id"]: h for r in own["repos"] if r["repo"] == "local" for h in r["hooks"]}
    for hook in _published_hooks():
        mine = local[hook["id"]]
        assert mine["entry"] == hook["entry"]
        assert mine["pass_filenames"] is hook["pass_filenames"] is False
        assert mine["language"] == "system"
        assert _folders(hook["files"]) <= _folders(mine["files"])


def _folders(pattern: str) -> set[str]:
    """`^(configs|models)/` -> {'configs', 'models'}; `^((configs|models)/|\\.robotconf\\.yaml$)`
    -> {'configs', 'models', '.robotconf.yaml'}."""
    match = re.fullmatch(r"\^\(([\w|-]+)\)/", pattern) or re.fullmatch(
        r"\^\(\(([\w|-]+)\)/\|((?:\\.|\w)+)\$\)", pattern
    )
    assert match, pattern
    files = {match.group(2).replace("\\", "")} if match.lastindex == 2 else set()
    return set(match.group(1).split("|")) | files


def test_the_published_hooks_run_in_an_install_made_as_pre_commit_makes_it(
    tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """pre-commit's `language: python` installs the package without extras plus the hook's
    `additional_dependencies`: in such a fresh environment each entry runs and judges the lab."""
    hooks = _published_hooks()
    extra = sorted({dep for hook in hooks for dep in hook.get("additional_dependencies", [])})
    env = fresh_install(tmp_path / "hook-env", shared_wheel(tmp_path_factory), *extra)
    lab = Lab(tmp_path / "fleet")
    for hook in hooks:
        program, *args = hook["entry"].split()
        done = subprocess.run(
            [str(env / "bin" / program), *args, "--repo", str(lab.root)],
            cwd=lab.root,
            env=clean_env(),
            capture_output=True,
            text=True,
            timeout=120,
        )
        if hook["id"] == "robotconf-schemas":  # the lab has no schemas/ yet: stale, and says so
            assert done.returncode == 1 and "robotconf schemas" in done.stderr + done.stdout
        else:
            assert done.returncode == 0, done.stderr
        assert "Traceback" not in done.stderr
