"""agent.yaml's `env:` for the brain: names, text values, ROS_DOMAIN_ID, the agent's own
variables refused, values never echoed; the brain's environment built from it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from robotconf.agent.config import AgentConfig, load_config
from robotconf.agent.process import brain_environment, request_environment
from robotconf.contract.launch import with_digest
from tests.support.agents import make_request
from tests.unit.agent.test_config import GOOD, problems, write

SECRET = "hunter2-secret"
KEY_LINE = GOOD.count("\n") + 2  # `env:` follows GOOD, its first key the line after


def env_problems(tmp_path: Path, env: str) -> list[str]:
    return problems(tmp_path, GOOD + env)


def test_env_loads_as_text(tmp_path: Path) -> None:
    config = load_config(
        write(
            tmp_path,
            GOOD + 'env: {ROS_DOMAIN_ID: "7", RMW_IMPLEMENTATION: rmw_cyclonedds_cpp, _x: ""}\n',
        )
    )
    assert config.env == {
        "ROS_DOMAIN_ID": "7",
        "RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp",
        "_x": "",
    }
    assert load_config(write(tmp_path, GOOD)).env == {}  # none by default


@pytest.mark.parametrize("name", ["1ROS", "ROS-DOMAIN", "A B", "ÄRGER", "x=y", '""'])
def test_env_names_are_variable_names_located_at_the_key(tmp_path: Path, name: str) -> None:
    found = env_problems(tmp_path, f"env:\n  {name}: v\n")
    shown = name.strip('"')
    assert found == [
        f"{KEY_LINE}: env.{shown}: is not an environment variable name: letters, digits and "
        "'_', not starting with a digit (e.g. ROS_DOMAIN_ID)"
    ]


@pytest.mark.parametrize("name", ["ROBOTCONF_LAUNCH_REQUEST", "ROBOTCONF_DIGEST", "robotconf_x"])
def test_the_agents_own_variables_are_refused(tmp_path: Path, name: str) -> None:
    (found,) = env_problems(tmp_path, f"env:\n  {name}: /tmp/other.json\n")
    assert found.startswith(f"{KEY_LINE}: env.{name}: is the agent's own")


@pytest.mark.parametrize("value", ["7", "0.5", "true", "[a]", "{a: b}"])
def test_values_are_text_and_never_echoed(tmp_path: Path, value: str) -> None:
    found = env_problems(tmp_path, f"env:\n  TOKEN: {value}\n")
    assert len(found) == 1 and found[0].startswith(f"{KEY_LINE}: env.TOKEN: "), found
    assert value not in found[0].removeprefix(f"{KEY_LINE}: env.TOKEN: ").replace('"7"', "")


def test_a_secret_in_a_bad_value_stays_out_of_the_message(tmp_path: Path) -> None:
    (found,) = env_problems(tmp_path, f'env:\n  TOKEN: "{SECRET}\\0"\n')
    assert (
        found
        == f"{KEY_LINE}: env.TOKEN: has a NUL character, which no environment variable can hold"
    )
    (found,) = env_problems(tmp_path, f"env:\n  TOKEN: {SECRET * 3000}\n")
    assert found == f"{KEY_LINE}: env.TOKEN: is longer than 32768 characters"


@pytest.mark.parametrize("domain", ["233", "-1", "seven", "7.0", " 7", "٧", ""])
def test_ros_domain_id_is_0_to_232(tmp_path: Path, domain: str) -> None:
    (found,) = env_problems(tmp_path, f'env:\n  ROS_DOMAIN_ID: "{domain}"\n')
    assert found.startswith(
        f"{KEY_LINE}: env: ROS_DOMAIN_ID {domain!r} is not a domain id: an integer"
    )


@pytest.mark.parametrize("domain", ["0", "101", "232"])
def test_ros_domain_ids_that_exist(tmp_path: Path, domain: str) -> None:
    config = load_config(write(tmp_path, GOOD + f'env: {{ROS_DOMAIN_ID: "{domain}"}}\n'))
    assert config.env["ROS_DOMAIN_ID"] == domain


def test_env_is_not_in_the_configs_repr(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, GOOD + f"env: {{TOKEN: {SECRET}}}\n"))
    assert SECRET not in repr(config) and SECRET not in str(config)
    assert isinstance(config, AgentConfig)


def test_the_brain_environment_adds_env_to_the_agents_own() -> None:
    built = brain_environment({"ROS_DOMAIN_ID": "7", "ROBOTCONF_ROBOT_ID": "tb3-01"})
    assert built[b"ROS_DOMAIN_ID"] == b"7" and built[b"ROBOTCONF_ROBOT_ID"] == b"tb3-01"
    assert built[b"PATH"] == os.environb[b"PATH"]  # the agent's own environment underneath


@pytest.mark.parametrize(
    ("inherited", "local", "domain", "expected", "conflict"),
    [
        (None, {}, None, None, False),  # no domain anywhere: none set
        (b"9", {}, None, b"9", False),  # the agent's own environment, as before domains
        (b"9", {}, 4, b"4", False),  # the repository's over the agent's environment
        (None, {"ROS_DOMAIN_ID": "7"}, 4, b"7", True),  # agent.yaml's wins, and is reported
        (None, {"ROS_DOMAIN_ID": "07"}, 7, b"07", False),  # the same domain: no conflict
        (None, {"ROS_DOMAIN_ID": "7"}, None, b"7", False),  # the request names none
    ],
)
def test_the_brains_environment_for_a_request(
    inherited: bytes | None,
    local: dict[str, str],
    domain: int | None,
    expected: bytes | None,
    conflict: bool,
) -> None:
    request = with_digest(make_request().model_copy(update={"ros_domain_id": domain}))
    own = {b"PATH": b"/usr/bin"} | ({} if inherited is None else {b"ROS_DOMAIN_ID": inherited})
    base = own | {k.encode(): v.encode() for k, v in local.items()}
    env, warnings = request_environment(base, local, request)
    assert env.get(b"ROS_DOMAIN_ID") == expected
    assert env[b"ROBOTCONF_DIGEST"] == request.digest.encode() and env[b"PATH"] == b"/usr/bin"
    assert len(warnings) == conflict
    assert base == own | {k.encode(): v.encode() for k, v in local.items()}  # left as it was
