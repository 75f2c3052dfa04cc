"""agent.yaml: valid files load with their defaults, every mistake is one line with file:line."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from robotconf.agent.cli import main
from robotconf.agent.config import ConfigInvalid, load_config
from tests.support.private import write_private

GOOD = """\
broker: mqtt://127.0.0.1:1883
prefix: robotconf
description: {id: tb3-01, name: Bot, recommended_template: turtlebot3-camera, platform: ROS2}
command: [python3, -m, cbs, --config, "{launch_request}"]
workdir: work
stop_timeout: 10
restart: {policy: on-failure, max_restarts: 5, backoff_initial: 1, backoff_max: 60}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "agent.yaml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def problems(tmp_path: Path, text: str) -> list[str]:
    path = write(tmp_path, text)
    with pytest.raises(ConfigInvalid) as caught:
        load_config(path)
    lines = [str(e) for e in caught.value.errors]
    prefix = f"{path}:"
    assert all(line.startswith(prefix) for line in lines), lines
    return [line[len(prefix) :] for line in lines]


def test_the_design_example_loads(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, GOOD))
    assert config.robot_id == "tb3-01"
    assert config.workdir == tmp_path / "work"  # relative to the file, not the cwd
    assert config.workdir.is_dir()
    assert config.restart.policy == "on-failure" and config.restart.max_restarts == 5
    assert config.description.to_wire().recommended_template == "turtlebot3-camera"
    assert config.connection().address.port == 1883


def test_defaults(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, "description: {id: r1}\ncommand: [brain]\nworkdir: w\n"))
    assert config.prefix == "robotconf"
    assert config.stop_timeout == 10 and config.startsecs == 1
    assert config.restart.backoff_max == 60 and config.log.backups == 3
    assert config.username is None and config.tls is None
    assert config.reload is None  # no reloads: every new request restarts the brain


@pytest.mark.parametrize("name", ["SIGHUP", "SIGUSR1", "SIGUSR2"])
def test_reload_names_a_signal_the_brain_catches(tmp_path: Path, name: str) -> None:
    config = load_config(write(tmp_path, GOOD + f"reload: {{signal: {name}}}\n"))
    assert config.reload is not None and config.reload.signal == name


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (
            "{signal: SIGTERM}",
            "8: reload.signal: 'SIGTERM' is not a signal a brain catches to reload; use one of "
            "SIGHUP, SIGUSR1, SIGUSR2, e.g. reload: {signal: SIGHUP}",
        ),
        ("{signal: SIGKILL}", "8: reload.signal: 'SIGKILL' is not a signal a brain catches"),
        ("{signal: hup}", "8: reload.signal: 'hup' is not a signal"),
        ("{signal: 1}", "8: reload.signal: 1 is not a signal a brain catches to reload"),
        ("{}", "8: 'reload.signal' is required; e.g. reload: {signal: SIGHUP}"),
        ("{signal: SIGHUP, after: 3}", "8: unknown key 'reload.after'; allowed here: signal"),
        ("SIGHUP", "8: reload is a mapping of its settings, e.g. reload: {signal: SIGHUP}"),
    ],
)
def test_a_bad_reload_is_one_located_line_saying_what_would_be_right(
    tmp_path: Path, value: str, expected: str
) -> None:
    found = problems(tmp_path, GOOD + f"reload: {value}\n")
    assert len(found) == 1 and found[0].startswith(expected), found


def test_a_near_miss_of_a_reload_signal_is_named(tmp_path: Path) -> None:
    found = problems(tmp_path, GOOD + "reload:\n  signal: sighup\n")
    assert found == [
        "9: reload.signal: 'sighup' is not a signal a brain catches to reload; use one of "
        "SIGHUP, SIGUSR1, SIGUSR2, e.g. reload: {signal: SIGHUP}; did you mean 'SIGHUP'?"
    ]


def test_unknown_keys_are_errors_with_their_line_and_a_suggestion(tmp_path: Path) -> None:
    found = problems(tmp_path, GOOD + "stop_timout: 3\nrestart_policy: always\n")
    assert found == [
        "8: unknown key 'stop_timout'; did you mean 'stop_timeout'?",
        "9: unknown key 'restart_policy'; did you mean 'restart'?",
    ]


def test_unknown_nested_keys_too(tmp_path: Path) -> None:
    text = GOOD.replace("{policy: on-failure,", "{polcy: on-failure,")
    assert problems(tmp_path, text) == ["7: unknown key 'restart.polcy'; did you mean 'policy'?"]
    text = GOOD.replace("platform: ROS2}", "platform: ROS2, colour: red}")
    found = problems(tmp_path, text)
    assert len(found) == 1 and found[0].startswith("3: unknown key 'description.colour'")


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("http://broker:1883", "must start with mqtt:// or mqtts://"),
        ("mqtt://:1883", "has no host"),
        ("mqtt://broker:99999", "is not valid"),
        ("mqtt://broker:1883/path", "must be only scheme://host:port"),
    ],
)
def test_bad_broker_url(tmp_path: Path, url: str, expected: str) -> None:
    found = problems(tmp_path, GOOD.replace("mqtt://127.0.0.1:1883", url))
    assert len(found) == 1
    assert found[0].startswith(f"1: broker URL '{url}'") and expected in found[0]


@pytest.mark.parametrize("robot_id", ["tb3 01", "tb3/01", "tb3+01", "-tb3", "x" * 65])
def test_robot_id_must_be_topic_safe(tmp_path: Path, robot_id: str) -> None:
    found = problems(tmp_path, GOOD.replace("id: tb3-01", f"id: '{robot_id}'"))
    assert len(found) == 1 and found[0].startswith("3: robot id") and "topic-safe" in found[0]


@pytest.mark.parametrize("command", ["[]", '[""]'])
def test_empty_command(tmp_path: Path, command: str) -> None:
    text = GOOD.replace('[python3, -m, cbs, --config, "{launch_request}"]', command)
    found = problems(tmp_path, text)
    assert len(found) == 1 and found[0].startswith("4: command is empty; give")


def test_command_is_never_a_shell_string(tmp_path: Path) -> None:
    shell = '"cbs --config {launch_request}"'
    text = GOOD.replace('[python3, -m, cbs, --config, "{launch_request}"]', shell)
    found = problems(tmp_path, text)
    assert len(found) == 1 and "never a shell string" in found[0]


def test_unwritable_workdir(tmp_path: Path) -> None:
    (tmp_path / "a-file").write_text("not a directory", encoding="utf-8")
    found = problems(tmp_path, GOOD.replace("workdir: work", "workdir: a-file/work"))
    assert len(found) == 1 and found[0].startswith("5: workdir ") and "not usable" in found[0]


def test_bad_prefix(tmp_path: Path) -> None:
    found = problems(tmp_path, GOOD.replace("prefix: robotconf", "prefix: lab/#"))
    assert len(found) == 1 and found[0].startswith("2: topic prefix 'lab/#'")


def test_numbers_out_of_range(tmp_path: Path) -> None:
    text = GOOD.replace("stop_timeout: 10", "stop_timeout: 0").replace(
        "backoff_initial: 1", "backoff_initial: 100"
    )
    found = problems(tmp_path, text)
    assert found[0].startswith("6: stop_timeout: Input should be greater than 0")
    assert found[1].startswith("7: restart: backoff_initial (100.0) is larger than backoff_max")


def test_credentials_and_tls(tmp_path: Path) -> None:
    write_private(tmp_path / "secret", "pw\n")
    (tmp_path / "ca.pem").write_text("", encoding="utf-8")
    text = GOOD.replace("mqtt://", "mqtts://") + (
        "username: tb3-01\npassword_file: secret\ntls: {ca_file: ca.pem}\n"
    )
    config = load_config(write(tmp_path, text))
    connection = config.connection()
    assert connection.address.tls and connection.password() == "pw"
    assert connection.ca_file == tmp_path / "ca.pem"


def test_credential_mistakes(tmp_path: Path) -> None:
    found = problems(tmp_path, GOOD + "username: tb3-01\npassword_file: missing\n")
    assert len(found) == 1 and "password_file: cannot read" in found[0]
    found = problems(tmp_path, GOOD + "password_file: missing\n")
    assert found == ["1: password_file is set but username is not; add username: ROBOT_USER"]
    found = problems(tmp_path, GOOD + "tls: {insecure: true}\n")
    assert len(found) == 1 and "tls options need a TLS broker URL" in found[0]


def test_public_key_must_be_an_ed25519_public_key(tmp_path: Path) -> None:
    (tmp_path / "key.pub").write_text("not a key", encoding="utf-8")
    found = problems(tmp_path, GOOD + "public_key: key.pub\n")
    assert len(found) == 1 and found[0].startswith("8: public_key: ") and "PEM" in found[0]


def test_yaml_problems(tmp_path: Path) -> None:
    twice = problems(tmp_path, GOOD + "workdir: other\n")
    assert twice == ["8: duplicate key 'workdir' (first at line 5); each key may appear once"]
    found = problems(tmp_path, "broker: [unclosed\n")
    assert len(found) == 1 and found[0].startswith("2: not valid YAML")
    assert problems(tmp_path, "- a list\n")[0].startswith("1: must be a mapping")


def test_missing_keys_name_what_is_needed(tmp_path: Path) -> None:
    found = problems(tmp_path, "broker: mqtt://h:1\n")
    assert [f.split(";")[0] for f in found] == [
        "1: 'command' is required",
        "1: 'description' is required",
        "1: 'workdir' is required",
    ]


def test_cli_reports_each_problem_on_one_line_and_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write(tmp_path, GOOD.replace("id: tb3-01", "id: 'tb3 01'") + "colour: red\n")
    assert main(["--config", str(path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2
    assert err[0].startswith(f"{path}:3: robot id 'tb3 01' is not topic-safe")
    assert err[1].startswith(f"{path}:8: unknown key 'colour'")


def test_cli_missing_file_and_bad_override(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--config", str(tmp_path / "nope.yaml")]) == 2
    assert "cannot read" in capsys.readouterr().err
    path = write(tmp_path, GOOD)
    assert main(["--config", str(path), "--broker", "tcp://x"]) == 2
    assert capsys.readouterr().err.startswith("--broker: broker URL 'tcp://x'")
    assert main(["--config", str(path), "--broker", "mqtt://other:1884", "--check"]) == 0
    assert main([]) == 2  # argparse's usage error, not a traceback


def test_workdir_is_made_private(tmp_path: Path) -> None:
    loose = tmp_path / "work"
    loose.mkdir(mode=0o755)
    loose.chmod(0o755)
    config = load_config(write(tmp_path, GOOD))
    assert config.workdir == loose
    assert loose.stat().st_mode & 0o777 == 0o700


def _tree(root: Path) -> list[tuple[str, int, int]]:
    return sorted(
        (str(p.relative_to(root)), p.lstat().st_mode, p.lstat().st_mtime_ns)
        for p in [root, *root.rglob("*")]
    )


def test_check_changes_nothing_on_disk(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD.replace("workdir: work", "workdir: state/work"))
    before = _tree(tmp_path)
    assert main(["--config", str(path), "--check"]) == 0
    assert _tree(tmp_path) == before  # the work directory is not made, nothing is probed
    # An unusable one is still reported, without being touched.
    (tmp_path / "state").write_text("a file where a folder should be\n")
    before = _tree(tmp_path)
    assert main(["--config", str(path), "--check"]) == 2
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("target", ["/dev/zero", "fifo"])
def test_an_agent_yaml_that_is_no_file_is_refused(tmp_path: Path, target: str) -> None:
    path = tmp_path / "agent.yaml"
    if target == "fifo":
        import os

        os.mkfifo(path)
    else:
        path.symlink_to(target)
    with pytest.raises(ConfigInvalid) as caught:
        load_config(path)
    assert "not a regular file" in str(caught.value.errors[0])


@pytest.mark.parametrize(
    ("line", "field"),
    [
        ('stop_timeout: "10"', "stop_timeout"),
        ("stop_timeout: true", "stop_timeout"),
        ('keepalive: "30"', "keepalive"),
        ('tls: {insecure: "yes"}', "tls.insecure"),
    ],
)
def test_values_have_their_own_type(tmp_path: Path, line: str, field: str) -> None:
    text = GOOD.replace("stop_timeout: 10\n", "") + line + "\n"
    found = problems(tmp_path, text)
    assert len(found) == 1 and field in found[0], found


def test_interfaces_reporting_is_off_unless_configured(tmp_path: Path) -> None:
    assert load_config(write(tmp_path, GOOD)).interfaces is None
    config = load_config(write(tmp_path, GOOD + "interfaces: {interval: 5}\n"))
    assert config.interfaces is not None and config.interfaces.command is None
    assert config.interfaces.interval == 5 and config.interfaces.timeout == 20
    command = "interfaces: {interval: 30, command: [/opt/bin/list-interfaces, --json], timeout: 4}"
    config = load_config(write(tmp_path, GOOD + command + "\n"))
    assert config.interfaces is not None
    assert config.interfaces.command == ["/opt/bin/list-interfaces", "--json"]


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("{command: [x]}", "8: 'interfaces.interval' is required; e.g. interfaces: {interval: 30}"),
        ("{interval: 0}", "8: interfaces.interval: Input should be greater than 0"),
        ("{interval: '5'}", "8: interfaces.interval must be a number, got '5' (text)"),
        ("{interval: 5, timeout: 0}", "8: interfaces.timeout: Input should be greater than 0"),
        ("{interval: 5, intervall: 3}", "8: unknown key 'interfaces.intervall'; did you mean"),
        ("30", "8: interfaces is a mapping of its settings, e.g. interfaces: {interval: 30}"),
        (
            "{interval: 5, command: 'ros2 topic list'}",
            "8: interfaces.command: must be an argument list, never a shell string",
        ),
        ("{interval: 5, command: []}", "8: interfaces.command: is empty; give a program"),
    ],
)
def test_a_bad_interfaces_section_is_one_located_line(
    tmp_path: Path, value: str, expected: str
) -> None:
    found = problems(tmp_path, GOOD + f"interfaces: {value}\n")
    assert len(found) == 1 and found[0].startswith(expected), found


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("fast", "restart.max_restarts must be a whole number, got 'fast' (text)"),
        ("2.5", "restart.max_restarts must be a whole number, got 2.5 (a number)"),
        ("[1]", "restart.max_restarts must be a whole number, got a list"),
    ],
)
def test_a_wrong_type_reads_naturally(tmp_path: Path, value: str, expected: str) -> None:
    text = GOOD.replace("max_restarts: 5", f"max_restarts: {value}")
    line = next(n for n, row in enumerate(text.splitlines(), 1) if row.startswith("restart:"))
    assert problems(tmp_path, text) == [f"{line}: {expected}"]


def test_the_goals_relay_settings_and_ready_timeout(tmp_path: Path) -> None:
    default = load_config(write(tmp_path, GOOD))
    assert default.ready_timeout == 120.0
    assert (default.goals.stale_after, default.goals.lines_per_second) == (300.0, 50.0)
    config = load_config(
        write(
            tmp_path,
            GOOD + "ready_timeout: 0\ngoals: {stale_after: 30, records_per_second: 2}\n",
        )
    )
    assert config.ready_timeout == 0 and config.goals.stale_after == 30
    assert config.goals.records_per_second == 2 and config.goals.lines_per_second == 50


def test_bad_goals_settings_are_located_lines(tmp_path: Path) -> None:
    found = problems(tmp_path, GOOD + "goals:\n  stale_after: 0\n  lines_per_secnd: 5\n")
    assert any(line.startswith("9:") and "stale_after" in line for line in found), found
    assert any(
        line.startswith("10:") and "did you mean 'lines_per_second'" in line for line in found
    ), found
    assert problems(tmp_path, GOOD + "ready_timeout: -1\n")[0].startswith("8:")
