"""agent.yaml through a real process: one line per problem, exit 2, never a traceback."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "agent.yaml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def test_cli_never_shows_a_traceback(tmp_path: Path) -> None:
    path = write(tmp_path, "description: {id: 'a b'}\ncommand: []\nworkdir: /proc/nope\n")
    result = subprocess.run(
        [sys.executable, "-m", "robotconf.agent.cli", "--config", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert len(result.stderr.splitlines()) == 2, result.stderr  # the id and the empty command
