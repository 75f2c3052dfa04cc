"""Labels and the rollout policy in fleet.yaml, validated: code, place and words per rule."""

from __future__ import annotations

import json

import pytest

from robotconf.contract.codes import Severity
from tests.support.lab import Lab

FLEET = "configs/fleet.yaml"
TB301 = "tb3-01: {scenario: delivery-gazebo, labels: {ring: canary, site: sim}, "


def enable_rollout(lab: Lab, waves: str, **fields: str) -> None:
    """fleet.yaml with a rollout policy of these waves (flow YAML) and fields."""
    extra = "".join(f"  {name}: {value}\n" for name, value in fields.items())
    lab.write(FLEET, lab.read(FLEET) + f"rollout:\n  waves: {waves}\n{extra}")


def line_starting(lab: Lab, prefix: str) -> int:
    """The line that starts with `prefix` (the commented example's lines start with '#')."""
    lines = lab.read(FLEET).splitlines()
    return next(n for n, line in enumerate(lines, start=1) if line.startswith(prefix))


def column_of(lab: Lab, line: int, needle: str) -> int:
    return lab.read(FLEET).splitlines()[line - 1].index(needle) + 1


def test_the_commented_example_policy_is_valid_when_uncommented(lab: Lab) -> None:
    text = lab.read(FLEET)
    assert "\n# rollout:\n" in text
    rollout = text.replace("\n# rollout:\n", "\nrollout:\n").replace("\n#   ", "\n  ")
    # Verification and stages are commented a column apart: uncommented with them alone.
    lab.write(FLEET, rollout.replace("\n# stages:", "\nstages:").replace("\n#  ", "\n  "))
    checked = lab.check()
    assert checked.diagnostics == []
    fleet = checked.repo.fleet.model if checked.repo.fleet else None
    rollout = fleet.rollout if fleet else None
    assert rollout is not None and [w.name for w in rollout.waves] == ["canary", "half", "all"]
    assert rollout.verify is not None and rollout.verify.success_rate == 0.9
    assert fleet is not None and [s.name for s in fleet.stages] == ["sim", "real"]


# ------------------------------------------------------------------ labels


@pytest.mark.parametrize("key", ["ring/x", "-ring", "a b", "x" * 65, "ring\n"])
def test_a_label_key_is_written_like_a_robot_id(lab: Lab, key: str) -> None:
    quoted = json.dumps(key)  # YAML's double-quoted scalars read JSON's escapes
    lab.replace(FLEET, "labels: {ring: canary, site: sim}", f"labels: {{{quoted}: canary}}")
    d = lab.only("RC502")
    assert f"label key {key!r} is not usable" in d.message
    assert d.line == lab.line_of(FLEET, "tb3-01:")
    assert d.col == column_of(lab, d.line, quoted)


def test_a_label_value_is_written_like_a_robot_id_and_is_located_at_the_value(lab: Lab) -> None:
    lab.replace(
        FLEET,
        "{ring: canary, site: sim}, namespace: tb3_01, name: Delivery",
        "{ring: 'can ary'}, name: X",
    )
    d = lab.only("RC502")
    assert "label 'ring' has value 'can ary', not usable" in d.message
    assert d.col == column_of(lab, d.line, "'can ary'")


def test_a_label_value_must_be_text(lab: Lab) -> None:
    lab.replace(FLEET, "{ring: canary, site: sim}", "{ring: 1}")
    assert lab.only("RC103").line == lab.line_of(FLEET, "tb3-01:")


# ------------------------------------------------------------------ the policy's own fields


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("healthy_after", "-1", "healthy_after is -1: seconds, 0 or more"),
        ("wave_timeout", "0", "wave_timeout is 0: seconds, more than 0"),
        ("max_failures", "-2", "max_failures is -2: a count"),
        ("max_failures", "'150%'", "max_failures is '150%'"),
        ("max_failures", "ten", "max_failures is 'ten'"),
        ("max_failures", "'١٠%'", "max_failures is '١٠%'"),
    ],
)
def test_policy_numbers_out_of_range(lab: Lab, field: str, value: str, words: str) -> None:
    enable_rollout(lab, "[{name: all}]", **{field: value})
    d = lab.only("RC702")
    assert words in d.message
    assert d.line == len(lab.read(FLEET).splitlines())  # the field, appended last
    assert d.col == len(f"  {field}: ") + 1


@pytest.mark.parametrize("value", ["0", "3", "'0%'", "'10%'", "'100%'"])
def test_failure_budgets_that_are_fine(lab: Lab, value: str) -> None:
    enable_rollout(lab, "[{name: all}]", max_failures=value, healthy_after="0")
    assert lab.check().diagnostics == []


@pytest.mark.parametrize("percent", [0, 101, -5])
def test_a_wave_percent_is_1_to_100(lab: Lab, percent: int) -> None:
    enable_rollout(lab, f"[{{name: some, percent: {percent}}}, {{name: all}}]")
    d = lab.only("RC702")
    assert f"wave 'some' has percent {percent}: 1 to 100" in d.message
    assert d.col == column_of(lab, d.line, f"{percent}}}")


def test_the_policy_is_typed_like_everything_else(lab: Lab) -> None:
    enable_rollout(lab, "[{name: all}]", on_failure="retry")
    assert lab.only("RC103").line == line_starting(lab, "  on_failure: retry")


# ------------------------------------------------------------------ wave names


def test_wave_names_are_unique(lab: Lab) -> None:
    enable_rollout(lab, "[{name: first, percent: 50}, {name: first}]")
    d = lab.only("RC701")
    line = line_starting(lab, "  waves:")
    assert d.message == f"wave name 'first' is used twice (first at line {line})"
    assert d.col == lab.read(FLEET).splitlines()[line - 1].rindex("first") + 1


@pytest.mark.parametrize("name", ["", "wave one", "all/1", "-x"])
def test_wave_names_are_written_like_robot_ids(lab: Lab, name: str) -> None:
    enable_rollout(lab, f"[{{name: {name!r}}}]")
    assert f"wave name {name!r} is not usable" in lab.only("RC701").message


# ------------------------------------------------------------------ selectors


def test_a_selector_key_no_robot_carries_is_an_error_with_a_hint(lab: Lab) -> None:
    enable_rollout(lab, "[{name: canary, selector: {rign: canary}}, {name: all}]")
    d = lab.only("RC703")
    assert d.message == (
        "wave 'canary' selects label 'rign', which no robot has; did you mean 'ring'?"
    )
    assert d.col == column_of(lab, d.line, "rign")


def test_a_selector_with_no_labels_in_the_fleet_says_none_exist(lab: Lab) -> None:
    lab.write(FLEET, "robots:\n  tb3-01: {scenario: delivery-gazebo}\n")
    enable_rollout(lab, "[{name: canary, selector: {ring: canary}}, {name: all}]")
    assert lab.only("RC703").message.endswith("which no robot has; none exist")


def test_a_selector_value_no_robot_has_is_an_error_with_a_hint(lab: Lab) -> None:
    enable_rollout(lab, "[{name: canary, selector: {ring: canarry}}, {name: all}]")
    d = lab.only("RC704")
    assert d.message == (
        "wave 'canary' selects ring: canarry, and no robot has that value; did you mean 'canary'?"
    )
    assert d.col == column_of(lab, d.line, "canarry")


def test_known_values_are_listed_when_none_is_close(lab: Lab) -> None:
    enable_rollout(lab, "[{name: hall, selector: {site: basement}}, {name: all}]")
    assert lab.only("RC704").message.endswith("; known: robotics-lab, sim")


# ------------------------------------------------------------------ every robot in a wave


def test_every_robot_must_fall_in_a_wave(lab: Lab) -> None:
    enable_rollout(
        lab, "[{name: canary, selector: {ring: canary}}, {name: sims, selector: {site: sim}}]"
    )
    d = lab.only("RC705")
    assert d.message == (
        "no wave takes robot(s) tb3-02, tb3-04, tb3-07, so no commit would ever reach them; add "
        "a last wave without selector, e.g. {name: all}"
    )
    assert (d.line, d.col) == (line_starting(lab, "  waves:"), 3)


def test_a_long_list_of_robots_left_out_is_cut_short(lab: Lab) -> None:
    extra = "".join(
        f"  tb3-{n}: {{scenario: guide-gazebo, namespace: tb3_{n}}}\n" for n in range(10, 16)
    )
    lab.replace(FLEET, "robots:\n", "robots:\n" + extra)
    enable_rollout(lab, "[{name: canary, selector: {ring: canary}}]")
    assert "tb3-02, tb3-04, tb3-05, tb3-07, tb3-10, ... (10 in all)" in lab.only("RC705").message


def test_a_wave_that_takes_no_robot_is_a_warning(lab: Lab) -> None:
    enable_rollout(lab, "[{name: all}, {name: canary, selector: {ring: canary}}]")
    d = lab.only("RC706")
    assert d.severity is Severity.WARNING
    assert d.message.startswith("wave 'canary' takes no robot")
    assert lab.check().ok
    assert d.col == column_of(lab, d.line, "canary")  # the wave's name


def test_a_percent_wave_after_its_share_is_taken_is_empty(lab: Lab) -> None:
    enable_rollout(lab, "[{name: most, percent: 80}, {name: half, percent: 50}, {name: all}]")
    assert lab.only("RC706").message.startswith("wave 'half' takes no robot")


def test_a_misspelt_selector_is_not_also_an_empty_wave(lab: Lab) -> None:
    enable_rollout(lab, "[{name: canary, selector: {ring: canarry}}, {name: all}]")
    assert [d.code for d in lab.check().diagnostics] == ["RC704"]


def test_a_fleet_of_labels_and_waves_that_fit_is_clean(lab: Lab) -> None:
    enable_rollout(
        lab,
        "[{name: canary, selector: {ring: canary}}, {name: lab, selector: {site: robotics-lab}}, "
        "{name: sims, selector: {site: sim}, percent: 100}, {name: all}]",
        max_failures="'10%'",
    )
    assert lab.check().diagnostics == []


def test_a_policy_without_waves_says_one_is_needed(lab: Lab) -> None:
    enable_rollout(lab, "[]")
    found = lab.only("RC103")
    assert found.line == line_starting(lab, "  waves:")
    assert "rollout.waves must be a list of at least 1 item" in found.message
