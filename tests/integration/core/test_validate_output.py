"""`robotconf validate` as CI and editors see it: exit codes, text, JSON and GitHub formats."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

from tests.support.lab import ROBOTCONF, Lab

DUPLICATE = "configs/capabilities/dup.yaml"
UNKNOWN = "configs/scenarios/typo.yaml"
LOOSE_SCHEME = "models/platforms/ROS2/mapping-schemes/bare.yaml"


def _two_errors(lab: Lab) -> None:
    lab.write(DUPLICATE, "platform: ROS2\nplatform: ROS2\n")
    lab.write(UNKNOWN, "capability: turtlebot3-camera\nenvironmnt: GazeboDemo1\n")


def _no_traceback(done: subprocess.CompletedProcess[str]) -> None:
    assert "Traceback" not in done.stdout + done.stderr, done.stderr


# ------------------------------------------------------------------ exit codes


def test_clean_example_lab_exits_0(lab: Lab) -> None:
    done = lab.run("validate")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout == ""
    assert re.fullmatch(r"\d+ files checked: no problems\n", done.stderr)


def test_repo_defaults_to_the_current_folder(lab: Lab) -> None:
    _two_errors(lab)
    done = subprocess.run(
        [ROBOTCONF, "validate"], cwd=lab.root, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 1
    assert f"{DUPLICATE}:2:1: error RC004 " in done.stdout


def test_errors_exit_1_sorted_and_counted(lab: Lab) -> None:
    _two_errors(lab)
    done = lab.run("validate")
    _no_traceback(done)
    assert done.returncode == 1
    lines = done.stdout.splitlines()
    assert lines == sorted(lines)
    assert f"{DUPLICATE}:2:1: error RC004 duplicate key 'platform' (first at line 1)" in lines[0]
    assert any(
        line.startswith(f"{UNKNOWN}:2:1: error RC101 ") and "did you mean 'environment'?" in line
        for line in lines
    )
    errors = len(lines)
    assert f": {errors} error(s), 0 warning(s)" in done.stderr


def test_warnings_alone_exit_0(lab: Lab) -> None:
    lab.write(LOOSE_SCHEME, "mappings: {}\n")
    done = lab.run("validate")
    assert done.returncode == 0, done.stdout
    assert done.stdout and all(
        line.startswith(f"{LOOSE_SCHEME}:") and " warning RC608 " in line
        for line in done.stdout.splitlines()
    )


def test_missing_repo_folder_is_a_tool_failure(tmp_path: Path) -> None:
    done = subprocess.run(
        [ROBOTCONF, "validate", "--repo", str(tmp_path / "nowhere")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    _no_traceback(done)
    assert done.returncode == 2
    assert done.stderr.startswith("robotconf: ") and "no such directory" in done.stderr
    assert done.stdout == ""


def test_unknown_revision_is_a_tool_failure(lab: Lab) -> None:
    lab.commit("lab")
    done = lab.run("validate", "--rev", "nosuchrev")
    _no_traceback(done)
    assert done.returncode == 2
    assert "'nosuchrev': no such revision" in done.stderr


def test_revision_outside_git_is_a_tool_failure(lab: Lab) -> None:
    done = lab.run("validate", "--rev", "HEAD")
    _no_traceback(done)
    assert done.returncode == 2
    assert "not a git repository" in done.stderr


def test_rev_reads_the_commit_not_the_work_tree(lab: Lab) -> None:
    lab.commit("clean")
    _two_errors(lab)
    assert lab.run("validate").returncode == 1
    assert lab.run("validate", "--rev", "HEAD").returncode == 0
    broken = lab.commit("broken")
    lab.remove(DUPLICATE)
    lab.remove(UNKNOWN)
    assert lab.run("validate").returncode == 0
    done = lab.run("validate", "--rev", broken)
    assert done.returncode == 1 and f"{DUPLICATE}:2:1: error RC004 " in done.stdout


# ------------------------------------------------------------------ --format json


def test_json_format_is_parseable_and_counts(lab: Lab) -> None:
    _two_errors(lab)
    lab.write(LOOSE_SCHEME, "mappings: {}\n")
    done = lab.run("validate", "--format", "json")
    assert done.returncode == 1
    report = json.loads(done.stdout)
    rows = report["diagnostics"]
    assert report["errors"] == sum(r["severity"] == "error" for r in rows) >= 2
    assert report["warnings"] == sum(r["severity"] == "warning" for r in rows) >= 1
    assert len(rows) == report["errors"] + report["warnings"]
    assert {
        "path": DUPLICATE,
        "line": 2,
        "col": 1,
        "severity": "error",
        "code": "RC004",
        "message": "duplicate key 'platform' (first at line 1); each key may appear once",
    } in rows
    for row in rows:
        assert set(row) == {"path", "line", "col", "severity", "code", "message"}
        assert isinstance(row["line"], int) and isinstance(row["col"], int)


def test_json_format_of_a_clean_repository(lab: Lab) -> None:
    done = lab.run("validate", "--format", "json")
    assert done.returncode == 0
    assert json.loads(done.stdout) == {"errors": 0, "warnings": 0, "diagnostics": []}


# ------------------------------------------------------------------ --format github


def test_github_format_annotates_each_finding(lab: Lab) -> None:
    _two_errors(lab)
    lab.write(LOOSE_SCHEME, "mappings: {}\n")
    done = lab.run("validate", "--format", "github")
    assert done.returncode == 1
    lines = done.stdout.splitlines()
    command = re.compile(
        r"^::(error|warning) file=([^,]+),line=(\d+),col=(\d+),title=(RC\d{3})::(.+)$"
    )
    assert all(command.match(line) for line in lines), lines
    assert (
        f"::error file={DUPLICATE},line=2,col=1,title=RC004::"
        "duplicate key 'platform' (first at line 1); each key may appear once"
    ) in lines
    assert any(line.startswith(f"::warning file={LOOSE_SCHEME},") for line in lines)
    # the same findings as the text format, one annotation each
    assert len(lines) == len(lab.run("validate").stdout.splitlines())


def test_github_format_escapes_properties(lab: Lab) -> None:
    lab.write("configs/capabilities/a,b:c.yaml", "platform: ROS2\nplatform: ROS2\n")
    done = lab.run("validate", "--format", "github")
    assert done.returncode == 1
    assert "::error file=configs/capabilities/a%2Cb%3Ac.yaml,line=2,col=1,title=RC004::" in (
        done.stdout
    )
