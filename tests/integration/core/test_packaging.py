"""The project's own packaging builds without deprecation noise (what `./dev setup` runs)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import zipfile
from importlib.metadata import version
from pathlib import Path

import pytest

from tests.support.install import PACKAGES, copy_project, shared_wheel

ROOT = Path(__file__).resolve().parents[3]

# pip's calls into the backend for `pip install -e .`, each in a process of its own; each read
# pyproject.toml and printed setuptools' license deprecation once. Run offline with this venv's
# setuptools, as `pip install --no-build-isolation` would.
_HOOK = """
import sys
from setuptools import build_meta as backend
print(getattr(backend, sys.argv[1])(*sys.argv[2:]))
"""
_HOOKS = (
    ("get_requires_for_build_editable",),
    ("prepare_metadata_for_build_editable", "meta"),
    ("build_editable", "dist"),
)


def _required_setuptools() -> int:
    # tomllib arrived in 3.11 and the project supports 3.10: the one line is enough.
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    found = re.search(r'^requires = \["setuptools>=(\d+)"\]$', text, re.MULTILINE)
    assert found, "build-system requires one setuptools>=N"
    return int(found.group(1))


def test_editable_build_prints_no_deprecation(tmp_path: Path) -> None:
    needed = _required_setuptools()
    have = version("setuptools")
    if int(have.split(".")[0]) < needed:
        pytest.skip(f"this venv's setuptools {have} predates {needed} (./dev setup installs it)")
    project = copy_project(tmp_path / "project")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    for hook, *folders in _HOOKS:
        outputs = [tmp_path / folder for folder in folders]
        for folder in outputs:
            folder.mkdir()
        done = subprocess.run(
            [sys.executable, "-c", _HOOK, hook, *map(str, outputs)],
            cwd=project,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        output = done.stdout + done.stderr
        assert done.returncode == 0, output
        assert "deprecat" not in output.lower(), f"{hook}:\n{output}"
    (wheel,) = (tmp_path / "dist").glob("robotconf-*.whl")
    with zipfile.ZipFile(wheel) as built:
        (metadata,) = (n for n in built.namelist() if n.endswith(".dist-info/METADATA"))
        text = built.read(metadata).decode()
        licenses = [n for n in built.namelist() if n.endswith("licenses/LICENSE")]
    assert "License-Expression: MIT" in text
    assert licenses, "the wheel carries the license file"


def test_the_wheel_carries_the_ui_script_and_stylesheet(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    """`robotconf ui` serves them from the package: no CDN, no build step."""
    with zipfile.ZipFile(shared_wheel(tmp_path_factory)) as built:
        names = set(built.namelist())
    assert {
        "robotconf/workstation/ui/static/ui.js",
        "robotconf/workstation/ui/static/ui.css",
    } <= names


def test_the_wheel_build_warns_of_nothing_and_carries_every_module(tmp_path: Path) -> None:
    """A fresh install builds the wheel: setuptools says nothing to warn of (a data folder
    outside `packages` did), and every module of the source is in it (a package list once
    left out workstation/desk, and `robotconf logs` with it)."""
    project = copy_project(tmp_path / "project")
    (tmp_path / "dist").mkdir()
    done = subprocess.run(
        [sys.executable, "-c", _HOOK, "build_wheel", str(tmp_path / "dist")],
        cwd=project,
        env={k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    # setuptools' warnings are classes (`_Warning`, `SetuptoolsDeprecationWarning`) framed in
    # `!!`; distutils' lower-case "warning: byte-compiling is disabled" is no packaging fault.
    for noise in ("Warning", "!!", "would be ignored", "eprecat"):
        assert noise not in output, output
    (wheel,) = (tmp_path / "dist").glob("robotconf-*.whl")
    with zipfile.ZipFile(wheel) as built:
        names = {n for n in built.namelist() if n.endswith(".py")}
    sources = {
        wheel_path(path.relative_to(project))
        for package in PACKAGES
        for path in (project / package).rglob("*.py")
    }
    assert sources - names == set()
    # One namespace (issue 33): nothing of ours lands beside robotconf in site-packages.
    with zipfile.ZipFile(wheel) as built:
        tops = {name.split("/")[0] for name in built.namelist()}
    assert {top for top in tops if not top.endswith(".dist-info")} == {"robotconf"}, tops


def wheel_path(source: Path) -> str:
    """Where a source file lands in the wheel: agent/cli.py as robotconf/agent/cli.py."""
    parts = source.parts if source.parts[0] == "robotconf" else ("robotconf", *source.parts)
    return "/".join(parts)
