"""Installs of robotconf as a user gets them: its wheel, built offline from a copy of this
checkout, put into a fresh virtual environment (no system site-packages, no PYTHONPATH)."""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.lab import ROOT

PACKAGES = (
    "contract",
    "configurator",
    "readmodel",
    "reconciler",
    "workstation",
    "agent",
    "robotconf",
)
INSTALL_TIMEOUT = 600


def clean_env() -> dict[str, str]:
    """No PYTHONPATH: the fresh environment must not see this checkout."""
    return {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "PYTHONHOME"}}


def run(argv: list[str], cwd: Path | None = None) -> str:
    """stdout of a command that must succeed; run outside the checkout, because `python -c`
    and `-m` put the working folder on sys.path."""
    done = subprocess.run(
        argv,
        cwd=cwd or Path("/"),
        env=clean_env(),
        capture_output=True,
        text=True,
        timeout=INSTALL_TIMEOUT,
        check=False,
    )
    assert done.returncode == 0, f"{' '.join(argv)}\n{done.stdout}\n{done.stderr}"
    return done.stdout


def copy_project(dest: Path) -> Path:
    """The files a build reads, copied so that the build's egg-info stays out of the checkout:
    the folders as they are, robotconf/'s links to them (robotconf/agent -> ../agent) kept."""
    dest.mkdir(parents=True)
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, dest / name)
    for package in PACKAGES:
        shutil.copytree(
            ROOT / package,
            dest / package,
            symlinks=True,
            ignore=shutil.ignore_patterns("__pycache__"),
        )
    return dest


def build_wheel(dest: Path) -> Path:
    """robotconf's wheel, built with this venv's setuptools from a copy of the project."""
    project = copy_project(dest / "project")
    wheels = dest / "wheels"
    pip = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation"]
    run([*pip, "-w", str(wheels), str(project)])
    (wheel,) = wheels.glob("robotconf-*.whl")
    return wheel


def shared_wheel(factory: pytest.TempPathFactory) -> Path:
    """robotconf's wheel, built once per test run and shared by every test that installs it:
    under pytest-xdist the workers' folders have one parent (the run's), and the first worker
    to ask builds it there while the others wait on a lock."""
    root = factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    with (root / "wheel.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        built = sorted((root / "shared-wheel" / "wheels").glob("robotconf-*.whl"))
        if built:
            return built[0]
        shutil.rmtree(root / "shared-wheel", ignore_errors=True)  # a build cut short
        return build_wheel(root / "shared-wheel")


def fresh_install(root: Path, wheel: Path, *requirements: str, decoys: bool = False) -> Path:
    """A new virtual environment under `root` with robotconf's `wheel` (and `requirements`)
    installed as pip resolves them from the package index; returns the environment. With
    `decoys`, packages of other people named `agent` and `contract` are there first."""
    env = root / "venv"
    run([sys.executable, "-m", "venv", str(env)])
    if decoys:
        add_decoys(env)
    run([str(env / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel), *requirements])
    return env


# Unrelated packages that share a name with a folder of this repository: a robot or a
# workstation may well hold an `agent` or a `contract` of its own.
DECOYS = ("agent", "contract")


def site_packages(env: Path) -> Path:
    """The environment's one site-packages folder."""
    (found,) = env.glob("lib/python3*/site-packages")
    return found


def add_decoys(env: Path) -> None:
    """Installs DECOYS into `env`, each a package that says whose it is (`OWNER`)."""
    for name in DECOYS:
        package = site_packages(env) / name
        package.mkdir()
        (package / "__init__.py").write_text(f'OWNER = "someone else\'s {name}"\n')
