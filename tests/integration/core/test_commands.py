"""The authoring and inspection commands (plan, autofill, tree, catalog, schemas) and the command
line itself: help, usage errors, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import click
import jsonschema
import pytest

from robotconf.configurator.loader import classify
from robotconf.configurator.plan import changed_fields
from robotconf.contract.yamlio import parse_document
from tests.support.lab import ROBOTCONF, ROOT, Lab

DELIVERY = "configs/scenarios/delivery-gazebo.yaml"
FLEET = "configs/fleet.yaml"


# ------------------------------------------------------------------ plan


def test_plan_names_changed_added_and_removed_robots(lab: Lab) -> None:
    lab.commit("base")
    assert lab.run("plan", "--base", "HEAD").returncode == 0  # nothing changed yet
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.12")
    lab.replace(FLEET, "  tb3-05:", "  tb3-09: {scenario: guide-gazebo}\n  tb3-05:")
    text = lab.read(FLEET)
    lab.write(FLEET, "\n".join(line for line in text.splitlines() if "tb3-04" not in line) + "\n")
    done = lab.run("plan", "--base", "HEAD", "--format", "json")
    assert done.returncode == 1, done.stderr
    plan = json.loads(done.stdout)
    by_robot = {c["robot_id"]: c for c in plan["changes"]}
    assert by_robot["tb3-01"]["change"] == "changed"
    assert by_robot["tb3-01"]["fields"] == ["scenario.logic_settings.follow_with_poses.move_speed"]
    assert by_robot["tb3-01"]["action"] == "reload"  # a setting: the capability is the same
    assert by_robot["tb3-09"]["change"] == "added" and by_robot["tb3-09"]["action"] == "start"
    assert by_robot["tb3-04"]["change"] == "removed" and by_robot["tb3-04"]["action"] == "stop"
    assert set(by_robot) == {"tb3-01", "tb3-09", "tb3-04"}


def test_plan_between_two_commits_and_markdown(lab: Lab) -> None:
    base = lab.commit("base")
    lab.replace(DELIVERY, "max_linear_speed: 0.2", "max_linear_speed: 0.25")
    head = lab.commit("faster")
    done = lab.run("plan", "--base", base, "--head", head, "--format", "markdown")
    assert done.returncode == 1
    assert (
        "| `tb3-01` | changed, reload | delivery-gazebo "
        "| `scenario.robot_settings.max_linear_speed` |" in (done.stdout)
    )
    text = lab.run("plan", "--base", base, "--head", head).stdout
    assert "~ tb3-01" in text and "1 changed, 0 added, 0 removed" in text
    assert "max_linear_speed [reload]" in text


def test_plan_says_restart_when_the_capability_changes(lab: Lab) -> None:
    base = lab.commit("base")
    # The same robot on the real-world mapping scheme: other topics, so another brain.
    lab.replace(
        "configs/capabilities/turtlebot3-camera.yaml",
        "mapping_scheme: gazebo",
        "mapping_scheme: real-world",
    )
    done = lab.run("plan", "--base", base, "--format", "json")
    by_robot = {c["robot_id"]: c for c in json.loads(done.stdout)["changes"]}
    assert by_robot["tb3-01"]["action"] == "restart", done.stdout


def test_plan_lists_the_wave_of_each_change_by_the_head_s_policy(lab: Lab) -> None:
    lab.commit("base")
    text = lab.read(FLEET)
    lab.write(FLEET, text.replace("\n# rollout:\n", "\nrollout:\n").replace("\n#   ", "\n  "))
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.12")
    done = lab.run("plan", "--base", "HEAD", "--format", "json")
    assert done.returncode == 1, done.stderr
    plan = json.loads(done.stdout)
    assert plan["waves"] == ["canary", "half", "all"] and plan["offline"] == "skip"
    assert [(c["robot_id"], c["wave"]) for c in plan["changes"]] == [("tb3-01", "canary")]
    assert "wave canary (1 of 3):\n  ~ tb3-01" in lab.run("plan", "--base", "HEAD").stdout


def test_plan_suspended_robot_is_held(lab: Lab) -> None:
    lab.commit("base")
    lab.replace(FLEET, "name: Delivery bot}", "name: Delivery bot, suspended: true}")
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 0.12")
    plan = json.loads(lab.run("plan", "--base", "HEAD", "--format", "json").stdout)
    assert [(c["robot_id"], c["change"]) for c in plan["changes"]] == [("tb3-01", "held")]


def test_plan_with_an_invalid_revision_is_a_tool_error(lab: Lab) -> None:
    lab.commit("base")
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 7")
    done = lab.run("plan", "--base", "HEAD")
    assert done.returncode == 2 and "RC403" in done.stderr and "head revision" in done.stderr
    done = lab.run("plan", "--base", "no-such-rev")
    assert done.returncode == 2
    assert "base revision does not exist: 'no-such-rev': no such revision" in done.stderr


def test_plan_from_a_base_that_does_not_validate_says_it_exists(lab: Lab) -> None:
    """A base that exists but does not validate is not read as "no such revision": its errors
    under a heading that says it exists, then why there is no plan."""
    lab.replace(DELIVERY, "move_speed: 0.1", "move_speed: 7")
    bad = lab.commit("too fast")
    lab.replace(DELIVERY, "move_speed: 7", "move_speed: 0.1")
    done = lab.run("plan", "--base", "HEAD")
    lines = done.stderr.splitlines()
    assert done.returncode == 2, done.stderr
    assert lines[0] == f"robotconf: base revision HEAD ({bad[:12]}) exists but does not validate:"
    assert "RC403" in lines[1] and len(lines) == 3
    assert lines[2].startswith(f"robotconf: base revision HEAD ({bad[:12]}) is invalid (1 error")
    assert "no robot runs it" in lines[2]


def test_changed_fields_walks_dicts_and_equal_length_lists() -> None:
    before = {"a": {"b": 1, "c": [1, {"d": 2}]}, "gone": 1}
    after = {"a": {"b": 1, "c": [1, {"d": 3}]}, "new": 1}
    assert changed_fields(before, after) == ["a.c[1].d", "gone", "new"]
    assert changed_fields({"l": [1]}, {"l": [1, 2]}) == ["l"]


# ------------------------------------------------------------------ autofill


def test_autofill_picks_logics_the_template_can_run(lab: Lab) -> None:
    done = lab.run(
        "autofill",
        "--platform",
        "ROS2",
        "--scheme",
        "gazebo",
        "--template",
        "turtlebot3-burger",
        "--name",
        "auto-burger",
    )
    assert done.returncode == 0, done.stderr
    path = "configs/capabilities/auto-burger.yaml"
    data = parse_document(path, lab.path(path).read_bytes()).data
    assert data["robot_template"] == "turtlebot3-burger"
    # The Burger has no camera: Follow falls back to Bluetooth; no door opener: no OpenDoor.
    assert data["actions"]["Follow"] == "follow_with_bluetooth"
    assert "OpenDoor" not in data["actions"]
    assert data["actions"]["SendGoalId"] == "send_goal_id"
    assert lab.read(path).startswith("# yaml-language-server: $schema=../../schemas/capability")
    assert lab.check().ok
    again = lab.run(
        "autofill",
        "--platform",
        "ROS2",
        "--scheme",
        "gazebo",
        "--template",
        "turtlebot3-burger",
        "--name",
        "auto-burger",
    )
    assert again.returncode == 1 and "exists" in again.stderr


def test_autofill_honours_requires(lab: Lab) -> None:
    """When AskHelp cannot run, SendGoalId (which requires it) is dropped too."""
    lab.replace("models/actions/AskHelp.yaml", "mappings: []", "mappings: [megaphone]")
    done = lab.run(
        "autofill",
        "--platform",
        "ROS2",
        "--scheme",
        "gazebo",
        "--template",
        "turtlebot3-waffle-pi",
        "--name",
        "auto",
    )
    assert done.returncode == 0, done.stderr
    data = parse_document("x", lab.path("configs/capabilities/auto.yaml").read_bytes()).data
    assert "AskHelp" not in data["actions"] and "SendGoalId" not in data["actions"]
    assert "skipped SendGoalId: requires AskHelp" in done.stdout
    assert [d for d in lab.check().errors if "auto.yaml" in d.path] == []


def test_autofill_all_selects_every_fitting_logic_and_the_file_validates(lab: Lab) -> None:
    args = ["autofill", "--platform", "ROS2", "--scheme", "gazebo"]
    done = lab.run(*args, "--template", "turtlebot3-waffle-pi", "--name", "every", "--all")
    assert done.returncode == 0, done.stderr
    path = "configs/capabilities/every.yaml"
    data = parse_document(path, lab.path(path).read_bytes()).data
    # The Waffle Pi has a camera and Bluetooth: both Follow logics; the rest has one each.
    assert data["actions"]["Follow"] == ["follow_with_poses", "follow_with_bluetooth"]
    assert data["actions"]["NavigateToLocation"] == "navigate_with_nav2"
    assert "  Follow: follow_with_poses, follow_with_bluetooth" in done.stdout
    assert "  Follow:\n    - follow_with_poses\n    - follow_with_bluetooth\n" in lab.read(path)
    # Without --all, the first fitting logic, as before.
    first = lab.run(*args, "--template", "turtlebot3-waffle-pi", "--name", "first")
    assert first.returncode == 0, first.stderr
    one = parse_document("x", lab.path("configs/capabilities/first.yaml").read_bytes()).data
    assert one["actions"]["Follow"] == "follow_with_poses"
    # One fitting logic is written as a name even with --all.
    burger = lab.run(*args, "--template", "turtlebot3-burger", "--name", "burger", "--all")
    assert burger.returncode == 0, burger.stderr
    assert "  Follow: follow_with_bluetooth\n" in lab.read("configs/capabilities/burger.yaml")
    assert lab.run("validate").returncode == 0


def test_validate_a_multi_logic_repository_and_its_errors(lab: Lab) -> None:
    either = "configs/capabilities/turtlebot3-follow-either.yaml"
    delivery = "configs/scenarios/delivery-gazebo.yaml"
    lab.replace(delivery, "capability: turtlebot3-camera", "capability: turtlebot3-follow-either")
    lab.replace(delivery, "logic_settings:\n", "logic_settings:\n  follow_with_bluetooth: {}\n")
    done = lab.run("validate")
    assert done.returncode == 0, done.stdout + done.stderr
    rendered = json.loads(lab.run("render", "tb3-01").stdout)
    logics = rendered["scenario"]["capability"]["logics"]
    assert logics["Follow"] == ["follow_with_poses", "follow_with_bluetooth"]
    lab.replace(
        either,
        "Follow: [follow_with_poses, follow_with_bluetooth]",
        "Follow: [follow_with_poses, follow_with_poses]",
    )
    done = lab.run("validate")
    line = lab.line_of(either, "Follow: [")
    assert done.returncode == 1
    assert f"{either}:{line}:" in done.stdout and "RC103" in done.stdout
    assert "'follow_with_poses' is named twice" in done.stdout
    assert "Traceback" not in done.stdout + done.stderr


def test_autofill_unknown_template(lab: Lab) -> None:
    done = lab.run(
        "autofill", "--platform", "ROS2", "--scheme", "gazebo", "--template", "turtlebot3-burgr"
    )
    assert done.returncode == 1 and "did you mean 'turtlebot3-burger'" in done.stderr


# ------------------------------------------------------------------ tree and catalog


def test_tree_shows_chosen_available_and_why_not(lab: Lab) -> None:
    done = lab.run("tree", "turtlebot3-bluetooth")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "✔ task Delivery: achieved by AskHelp, SendGoalId, Follow" in out
    assert "● follow_with_bluetooth (chosen)" in out
    assert "✗ follow_with_poses: robot template lacks camera" in out
    assert "○ task Patrol: not achievable" in out
    assert lab.run("tree", "turtlebot3-bluetoth").returncode == 1


def test_tree_says_why_an_action_is_unavailable(lab: Lab) -> None:
    out = lab.run("tree", "noetic-patrol").stdout
    assert "action Follow (not selected; for ROS2, not ROS1)" in out
    assert "action SendGoalId (not selected; requires AskHelp (not selected))" in out


def test_catalog_lists_what_exists(lab: Lab) -> None:
    data = json.loads(lab.run("catalog", "--json").stdout)
    assert set(data["platforms"]) == {"ROS1", "ROS2"}
    assert set(data["actions"]["Follow"]["logics"]) == {
        "follow_with_poses",
        "follow_with_bluetooth",
    }
    assert data["tasks"]["Patrol"] == [["NavigateToLocation"], ["OpenDoor", "NavigateToLocation"]]
    assert "GazeboDemo1" in data["environments"]
    text = lab.run("catalog").stdout
    assert "logic follow_with_poses: needs odometry, cmd_vel, camera" in text


# ------------------------------------------------------------------ schemas


def test_schemas_are_current_in_this_repository() -> None:
    from robotconf.workstation.cli.main import main

    assert main(["schemas", "--check", "--repo", str(ROOT)]) == 0


def test_schemas_go_stale_when_the_catalogue_changes(lab: Lab) -> None:
    assert lab.run("schemas").returncode == 0
    assert lab.run("schemas", "--check").returncode == 0
    lab.write(
        "models/actions/Wave.yaml",
        "platforms: [ROS2]\nlogics:\n  wave_arm: {mappings: [arm]}\n",
    )
    done = lab.run("schemas", "--check")
    assert done.returncode == 1 and "capability.schema.json" in done.stderr
    lab.run("schemas")
    schema = json.loads(lab.read("schemas/capability.schema.json"))
    wave = schema["properties"]["actions"]["properties"]["Wave"]
    assert wave["anyOf"][0] == {"const": "wave_arm", "description": "(needs mappings: arm)"}
    several = wave["anyOf"][1]  # or a list of its logics, each once
    assert several["items"] == {"enum": ["wave_arm"]} and several["uniqueItems"] is True


def _schema_for(rel: str) -> dict[str, object]:
    found = classify(rel)
    assert found is not None
    loaded: dict[str, object] = json.loads(
        (ROOT / "schemas" / f"{found[0].name}.schema.json").read_text(encoding="utf-8")
    )
    return loaded


@pytest.mark.parametrize(
    "rel",
    sorted(
        p.relative_to(ROOT).as_posix()
        for top in ("configs", "models")
        for p in (ROOT / top).rglob("*.yaml")
    ),
)
def test_every_example_file_fits_its_generated_schema_and_names_it(rel: str) -> None:
    raw = (ROOT / rel).read_bytes()
    jsonschema.validate(parse_document(rel, raw).data, _schema_for(rel))
    first = raw.decode("utf-8").splitlines()[0]
    found = classify(rel)
    assert found is not None
    assert first.startswith("# yaml-language-server: $schema=")
    assert first.endswith(f"schemas/{found[0].name}.schema.json")
    target = (ROOT / rel).parent / first.split("$schema=", 1)[1]
    assert target.resolve().is_file()


def test_capability_schema_refuses_what_does_not_exist() -> None:
    schema = _schema_for("configs/capabilities/x.yaml")
    good = {
        "platform": "ROS2",
        "mapping_scheme": "gazebo",
        "actions": {"Follow": "follow_with_poses"},
    }
    jsonschema.validate(good, schema)
    for bad in (
        {**good, "platform": "ROS3"},
        {**good, "mapping_scheme": "gazebo-classic"},  # a ROS1 scheme
        {**good, "actions": {"Follow": "follow_with_pose"}},
        {**good, "actions": {"Folow": "follow_with_poses"}},
        {**good, "extra": 1},
    ):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)


# ------------------------------------------------------------------ the command line itself


def robotconf(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [ROBOTCONF, *args], capture_output=True, text=True, timeout=120, cwd=ROOT, env=env
    )


def test_help_lists_every_command_the_table_declares() -> None:
    from robotconf.workstation.cli.main import COMMANDS

    done = robotconf("--help")
    assert done.returncode == 0, done.stderr
    section = done.stdout.split("Commands:")[1].splitlines()
    # A command's line starts two spaces in; a wrapped help text continues further in.
    listed = [line.split()[0] for line in section if line.startswith("  ") and line[2] != " "]
    assert listed == list(COMMANDS)
    assert "agent" in listed and "broker-config" in listed


def test_every_table_entry_loads_the_command_it_names() -> None:
    from robotconf.workstation.cli.main import COMMANDS, cli

    ctx = click.Context(cli)
    for name in COMMANDS:
        command = cli.get_command(ctx, name)
        assert isinstance(command, click.Command) and command.name == name


def test_agent_help_is_the_agents_own() -> None:
    done = robotconf("agent", "--help")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: robotconf agent") and "--config PATH" in done.stdout


def test_agent_arguments_pass_through(tmp_path: Path) -> None:
    done = robotconf("agent", "--config", str(tmp_path / "missing.yaml"), "--check")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "missing.yaml" in done.stderr


@pytest.mark.parametrize(
    "args",
    [
        ("no-such-command",),
        ("validate", "--format", "xml"),
        ("plan", "--wait", "soon"),
        ("status", "--wait", "soon"),
        ("keys", "make"),
    ],
)
def test_usage_errors_exit_2(args: tuple[str, ...]) -> None:
    done = robotconf(*args)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Usage: robotconf" in done.stderr and "Traceback" not in done.stderr


def test_a_cli_error_is_one_line_with_its_code(capsys: pytest.CaptureFixture[str]) -> None:
    from robotconf.contract.errors import CliError, ExitCode
    from robotconf.workstation.cli.main import cli, main

    @cli.command("fails-for-test")
    def fails() -> None:
        raise CliError("it went wrong", ExitCode.FINDINGS)

    @cli.command("crashes-for-test")
    def crashes() -> None:
        raise RuntimeError("surprise")

    try:
        assert main(["fails-for-test"]) == 1
        assert capsys.readouterr().err == "robotconf: it went wrong\n"
        assert main(["crashes-for-test"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("robotconf: internal error: RuntimeError: surprise")
        assert len(err.splitlines()) == 1
    finally:
        cli.commands.pop("fails-for-test")
        cli.commands.pop("crashes-for-test")


def test_a_command_without_the_server_extra_says_what_to_install() -> None:
    code = (
        "import sys; sys.modules['rich'] = None  # as if rich were not installed\n"
        "from robotconf.workstation.cli import main\n"
        "sys.exit(main(['catalog', '--repo', sys.argv[1]]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(ROOT)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2
    assert done.stderr == (
        "robotconf: robotconf catalog needs the server extra (rich is not installed): "
        "pip install 'robotconf[server]'\n"
    )


def test_version() -> None:
    done = robotconf("--version")
    assert done.returncode == 0 and done.stdout.startswith("robotconf ")
