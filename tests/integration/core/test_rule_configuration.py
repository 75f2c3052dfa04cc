"""`robotconf validate` with the rules a lab tuned (issue 21, item 6): `.robotconf.yaml` read from
the work tree or the commit like every file, and `# robotconf: ignore` comments, in every format."""

from __future__ import annotations

import json
import os
import subprocess

from tests.support.lab import ROBOTCONF, Lab

FLEET = "configs/fleet.yaml"
CONFIG = ".robotconf.yaml"
# A second real-world robot beside tb3-04, without a namespace: the same absolute names (RC505).
TWIN = "  tb3-06: {scenario: patrol-real, name: Twin}\n"


def _twin(lab: Lab, comment: str = "") -> int:
    """Adds the twin robot last (with `comment` on its line): the line RC505 is reported at."""
    lines = lab.read(FLEET).splitlines()
    last = next(i for i, line in enumerate(lines) if line.startswith("  tb3-05:"))
    lab.replace(FLEET, lines[last] + "\n", lines[last] + "\n" + TWIN.rstrip("\n") + comment + "\n")
    return last + 2


def _lines(done: subprocess.CompletedProcess[str]) -> list[str]:
    assert "Traceback" not in done.stderr, done.stderr
    return done.stdout.splitlines()


def test_a_rule_turned_down_to_a_warning_no_longer_fails_validate(lab: Lab) -> None:
    line = _twin(lab)
    refused = lab.run("validate")
    assert refused.returncode == 1
    assert [x.split(" ", 2)[:2] for x in _lines(refused)] == [[f"{FLEET}:{line}:3:", "error"]]
    lab.write(CONFIG, "rules:\n  RC505: warning  # the twins run on two ROS domains\n")
    done = lab.run("validate")
    assert done.returncode == 0, done.stdout
    assert _lines(done) == [_lines(refused)[0].replace(" error RC505 ", " warning RC505 ")]
    report = json.loads(lab.run("validate", "--format", "json").stdout)
    assert (report["errors"], report["warnings"]) == (0, 1)
    github = lab.run("validate", "--format", "github")
    assert github.returncode == 0
    assert github.stdout.startswith(f"::warning file={FLEET},line={line},col=3,title=RC505::")


def test_a_rule_turned_off_is_not_reported(lab: Lab) -> None:
    _twin(lab)
    lab.write(CONFIG, "rules: {RC505: off}\n")
    done = lab.run("validate")
    assert (done.returncode, _lines(done)) == (0, [])
    assert "no problems" in done.stderr


def test_an_ignore_comment_silences_the_finding_on_its_line(lab: Lab) -> None:
    _twin(lab, "  # robotconf: ignore RC505 (two ROS domains)")
    done = lab.run("validate")
    assert (done.returncode, _lines(done)) == (0, [])


def test_an_unused_or_unknown_ignore_is_reported_at_the_comment(lab: Lab) -> None:
    lab.replace(FLEET, "robots:\n", "robots:  # robotconf: ignore RC505, RC50\n")
    done = lab.run("validate")
    assert done.returncode == 0  # warnings: they silence nothing, they break nothing
    assert [x.split(" (", 1)[0].split(";")[0] for x in _lines(done)] == [
        f"{FLEET}:2:30: warning RC803 `# robotconf: ignore RC505` silences nothing: no RC505 "
        "finding on line 2",
        f"{FLEET}:2:37: warning RC802 'RC50' is not a rule code, so it silences nothing",
    ]


def test_a_rule_a_lab_cannot_tune_is_refused_in_either_place(lab: Lab) -> None:
    lab.replace(
        FLEET,
        "robots:\n",
        "robots:\n  tb3/09: {scenario: guide-gazebo, namespace: tb3_09}"
        "  # robotconf: ignore RC501\n",
    )
    lab.write(CONFIG, "rules:\n  RC501: off\n")
    lines = _lines(lab.run("validate"))
    assert [x.split(" ", 3)[:3] for x in lines] == [
        [f"{CONFIG}:2:3:", "error", "RC801"],
        [f"{FLEET}:3:3:", "error", "RC501"],
        [f"{FLEET}:3:76:", "warning", "RC802"],
    ]
    assert "RC501 cannot be tuned: ids, labels and names become MQTT topic levels" in lines[0]


def test_the_configuration_is_read_like_every_file(lab: Lab) -> None:
    lab.write(CONFIG, "rules: {RC505: of}\n")
    done = lab.run("validate")
    assert done.returncode == 1
    assert _lines(done) == [
        f"{CONFIG}:1:16: error RC801 RC505: 'of' is not a severity; use error, warning or off"
    ]
    lab.write(CONFIG, "rule: {RC505: off}\nrules:\n  RC505: off\n  RC505: warning\n")
    codes = [x.split(" ")[:3] for x in _lines(lab.run("validate"))]
    assert codes == [[f"{CONFIG}:4:3:", "error", "RC004"]]  # the strict reader, as for all files
    lab.write(CONFIG, "rule: {RC505: off}\n")
    assert [x.split(" ")[2] for x in _lines(lab.run("validate"))] == ["RC101"]
    os.remove(lab.path(CONFIG))
    os.symlink(lab.path(FLEET), lab.path(CONFIG))
    assert [x.split(" ")[:3] for x in _lines(lab.run("validate"))] == [
        [f"{CONFIG}:1:1:", "error", "RC008"]
    ]


def test_rev_reads_the_configuration_of_the_commit(lab: Lab) -> None:
    _twin(lab)
    lab.write(CONFIG, "rules: {RC505: off}\n")
    tuned = lab.commit("the twins are on two domains")
    lab.remove(CONFIG)
    assert lab.run("validate").returncode == 1  # the work tree has no configuration now
    assert lab.run("validate", "--rev", tuned).returncode == 0
    untuned = lab.commit("no configuration")
    assert lab.run("validate", "--rev", untuned).returncode == 1
    assert lab.run("validate", "--rev", tuned).returncode == 0


def test_validate_help_names_the_configuration() -> None:
    done = subprocess.run([ROBOTCONF, "validate", "--help"], capture_output=True, text=True)
    assert ".robotconf.yaml" in done.stdout and "# robotconf: ignore" in done.stdout


def test_plan_judges_each_revision_with_its_own_configuration(lab: Lab) -> None:
    base = lab.commit("the lab")
    _twin(lab)
    refused = lab.run("plan", "--base", base)
    assert refused.returncode == 2 and "head revision (work tree) is invalid" in refused.stderr
    lab.write(CONFIG, "rules: {RC505: off}\n")
    head = lab.commit("a twin on its own ROS domain")
    done = lab.run("plan", "--base", base, "--head", head, "--format", "json")
    assert done.returncode == 1, done.stderr
    assert [c["robot_id"] for c in json.loads(done.stdout)["changes"]] == ["tb3-06"]
    lab.remove(CONFIG)
    untuned = lab.commit("the configuration removed, nothing else")
    again = lab.run("plan", "--base", head, "--head", untuned)
    assert again.returncode == 2 and f"head revision {untuned} ({untuned[:12]}) is invalid" in (
        again.stderr
    )
