"""A copy of the example lab in a temporary folder, edited by tests and checked in-process."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from robotconf.configurator.render import render_robot
from robotconf.configurator.workspace import Checked, check
from robotconf.contract.diagnostics import Diagnostic
from robotconf.contract.launch import LaunchRequest

ROOT = Path(__file__).resolve().parents[2]
ROBOTCONF = str(Path(sys.executable).parent / "robotconf")


class Lab:
    def __init__(self, root: Path) -> None:
        self.root = root
        for part in ("models", "configs"):
            shutil.copytree(ROOT / part, root / part)

    def path(self, rel: str) -> Path:
        return self.root / rel

    def read(self, rel: str) -> str:
        return self.path(rel).read_text(encoding="utf-8")

    def write(self, rel: str, text: str) -> None:
        target = self.path(rel)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")

    def replace(self, rel: str, old: str, new: str) -> None:
        text = self.read(rel)
        assert old in text, f"{old!r} not in {rel}"
        self.write(rel, text.replace(old, new, 1))

    def remove(self, rel: str) -> None:
        self.path(rel).unlink()

    def check(self, rev: str | None = None) -> Checked:
        return check(self.root, rev)

    def render(self, robot_id: str = "tb3-01", rev: str | None = None) -> LaunchRequest:
        """A robot's Launch Request from the work tree (or `rev`), which must be valid."""
        checked = self.check(rev)
        assert checked.ok, checked.errors
        return render_robot(checked.repo, robot_id)

    def diagnostics(self, code: str) -> list[Diagnostic]:
        return [d for d in self.check().diagnostics if d.code == code]

    def only(self, code: str) -> Diagnostic:
        """The one diagnostic of the repository, which must have this code."""
        found = self.check().diagnostics
        assert [d.code for d in found] == [code], "\n".join(map(str, found))
        return found[0]

    def line_of(self, rel: str, needle: str) -> int:
        for number, line in enumerate(self.read(rel).splitlines(), start=1):
            if needle in line:
                return number
        raise AssertionError(f"{needle!r} not in {rel}")

    def run(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [ROBOTCONF, *args, "--repo", str(self.root)],
            capture_output=True,
            text=True,
            timeout=120,
        )

    def git(self, *args: str) -> str:
        done = subprocess.run(
            ["git", *args], cwd=self.root, capture_output=True, text=True, check=True
        )
        return done.stdout.strip()

    def commit(self, message: str) -> str:
        if not (self.root / ".git").exists():
            self.git("init", "-q", "-b", "main")
            self.git("config", "user.email", "lab@example.org")
            self.git("config", "user.name", "Lab")
        self.git("add", "-A")
        self.git("commit", "-q", "-m", message)
        return self.git("rev-parse", "HEAD")
