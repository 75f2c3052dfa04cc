"""No name or value from a file can forge a line of what robotconf prints or reach the terminal
raw (issue 10, item 10): validate, plan and render as real processes."""

from __future__ import annotations

import json

import pytest

from tests.support.lab import Lab

FLEET = "configs/fleet.yaml"
SCENARIO = "configs/scenarios/delivery-gazebo.yaml"
FORGED = "configs/fleet.yaml:1:1: error RC999 forged"
# YAML double-quoted escapes: a newline, ESC (a terminal's escape), a line separator, a bidi
# override; none of them may come out raw.
HOSTILE_KEY = '"a\\n' + FORGED + '\\e[2J\\L\\u202e"'


def assert_clean(text: str) -> None:
    for char in ("\x1b", "\u2028", "\u202e", "\x85"):
        assert char not in text
    assert not any(line.startswith(FORGED) for line in text.splitlines())


@pytest.mark.parametrize("fmt", ["text", "github", "json"])
def test_a_key_cannot_forge_a_diagnostic(lab: Lab, fmt: str) -> None:
    lab.write(FLEET, lab.read(FLEET) + f"{HOSTILE_KEY}: 1\n")
    done = lab.run("validate", "--format", fmt)
    assert done.returncode == 1
    assert_clean(done.stdout + done.stderr)
    if fmt == "text":
        assert len(done.stdout.splitlines()) == 1
        assert "\\n" + FORGED in done.stdout and "\\x1b[2J" in done.stdout
    elif fmt == "github":
        assert len(done.stdout.splitlines()) == 1 and done.stdout.startswith("::error ")
    else:
        (row,) = json.loads(done.stdout)["diagnostics"]
        assert FORGED in row["message"]


def test_plan_and_render_escape_what_they_show(lab: Lab) -> None:
    lab.commit("base")
    lab.replace(SCENARIO, "knowledge: {", f"knowledge: {{{HOSTILE_KEY}: 1, ")
    for fmt in ("text", "markdown"):
        done = lab.run("plan", "--base", "HEAD", "--format", fmt)
        assert done.returncode == 1, done.stderr
        assert_clean(done.stdout)
        changed = [line for line in done.stdout.splitlines() if "tb3-01" in line]
        assert len(changed) == 1 and "environment_knowledge" in changed[0]
    done = lab.run("render", "tb3-01")
    assert done.returncode == 0
    assert_clean(done.stdout)
    knowledge = json.loads(done.stdout)["scenario"]["environment_knowledge"]
    assert any(FORGED in key and "\u202e" in key for key in knowledge)  # same data, escaped
