"""The table of topics (contract/topics.py) is the one source: the broker ACL `broker-config`
writes and the rules `up`'s embedded broker checks agree on every row, role and id, and the docs'
page is the table."""

from __future__ import annotations

import importlib
import re

import pytest

from robotconf.configurator.brokerconf import ServiceUsers, render_acl
from robotconf.contract.topics import BY_KEY, TOPICS, Role, grants, subscriptions
from robotconf.contract.wire import Topics, agent_client_id
from robotconf.workstation.docs import topics_page
from tests.support.lab import ROOT

PREFIX = "lab1/robotconf"
ROBOTS = ["tb3-01", "tb3-02"]


def _matches(rule: str, topic: str) -> bool:
    """MQTT's matching of a concrete topic against a filter (`+` one level, `#` the rest)."""
    ours, theirs = rule.split("/"), topic.split("/")
    for index, level in enumerate(ours):
        if level == "#":
            return True
        if index >= len(theirs) or level not in ("+", theirs[index]):
            return False
    return len(ours) == len(theirs)


def acl_allows(acl: str, user: str, client: str, topic: str, want: str) -> bool:
    """The ACL file read as the broker reads it, independently of contract/topics.py: `pattern`
    lines for everyone with %u and %c replaced (not for an id holding a wildcard or '/'),
    `topic` lines for the `user` above them; whatever no line allows is denied."""
    rules: list[tuple[str, str]] = []
    current = None
    for line in acl.splitlines():
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0] == "user":
            current = words[1]
        elif words[0] == "pattern":
            used = [i for key, i in (("%u", user), ("%c", client)) if key in words[2]]
            if not any(set("/+#") & set(i) for i in used):
                rules.append((words[1], words[2].replace("%u", user).replace("%c", client)))
        elif words[0] == "topic":
            if current == user:
                rules.append((words[1], words[2]))
        else:
            raise AssertionError(f"an ACL line this reading does not know: {line!r}")
    return any(want in access and _matches(rule, topic) for access, rule in rules)


def concrete_topics() -> list[str]:
    found = [t.name(PREFIX, r, c) for t in TOPICS for r in ROBOTS for c in ("c1", "c2")]
    found += [f"{PREFIX}/robots/tb3-01/launch/more", f"{PREFIX}/other", "robotconf/robots/x/launch"]
    return sorted(set(found))


@pytest.mark.parametrize("users", [ServiceUsers(), ServiceUsers("rec", "look", "ops")])
def test_the_acl_and_the_embedded_broker_decide_alike_for_every_row_role_and_id(
    users: ServiceUsers,
) -> None:
    acl = render_acl(PREFIX, ROBOTS, users)
    clients = [
        (user, client)
        for user in [*ROBOTS, *sorted(users.names()), "+", "a/b"]
        for client in (user, agent_client_id(user), "c1")
    ]
    allowed = 0
    for user, client in clients:
        rules = grants(PREFIX, user, client, users.roles())
        for topic in concrete_topics():
            for want, decide in (("read", rules.may_read), ("write", rules.may_write)):
                expected = acl_allows(acl, user, client, topic, want)
                assert decide(topic) == expected, (user, client, topic, want)
                allowed += expected
    assert allowed > 100  # the comparison is not between two refusals of everything


@pytest.mark.parametrize("topic", TOPICS, ids=lambda t: t.key)
def test_each_role_may_do_what_its_row_says(topic: object) -> None:
    assert hasattr(topic, "key")
    row = BY_KEY[topic.key]  # type: ignore[attr-defined]
    users = ServiceUsers()
    for role in Role:
        user = "tb3-01" if role is Role.ROBOT else users.name(role)
        rules = grants(PREFIX, user, "c1", users.roles())
        own = row.name(PREFIX, "tb3-01", "c1")
        assert rules.may_read(own) == (role in row.read), (role, row.key)
        assert rules.may_write(own) == (role in row.write), (role, row.key)
        if row.per_robot and role is Role.ROBOT:  # a robot's rights end at its own topics
            other = row.name(PREFIX, "tb3-02")
            assert not rules.may_read(other) and not rules.may_write(other)


def test_a_robot_may_subscribe_to_its_own_topics_only() -> None:
    robot = grants(PREFIX, "tb3-01", "tb3-01", ServiceUsers().roles())
    assert robot.may_subscribe(f"{PREFIX}/robots/tb3-01/launch")
    assert robot.may_subscribe(f"{PREFIX}/robots/tb3-01/logs/request")
    for refused in ("robots/+/launch", "robots/tb3-02/logs/request", "#", "robots/tb3-01/#"):
        assert not robot.may_subscribe(f"{PREFIX}/{refused}"), refused
    reconciler = grants(PREFIX, "reconciler", "r", ServiceUsers().roles())
    assert reconciler.may_subscribe(f"{PREFIX}/robots/+/launch")
    assert reconciler.may_subscribe(f"{PREFIX}/robots/tb3-01/status")
    assert not reconciler.may_subscribe(f"{PREFIX}/robots/+/logs")
    assert not reconciler.may_subscribe(f"{PREFIX}/#")


def test_subscriptions_come_from_the_table_and_refuse_a_row_the_role_may_not_read() -> None:
    topics = Topics(PREFIX)
    assert subscriptions(Role.ROBOT, PREFIX, robot_id="r1") == [
        topics.launch("r1"),
        topics.status("r1"),
        topics.restart("r1"),
        topics.logs_request("r1"),
    ]
    assert subscriptions(Role.VIEWER, PREFIX) == [
        topics.all_launch,
        topics.all_status,
        topics.all_description,
        topics.all_interfaces,
        topics.all_goals,  # the outcomes stream is asked for by name only
        topics.reconciler_status,
    ]
    assert subscriptions(Role.VIEWER, PREFIX, "goal_outcomes") == [topics.all_goal_outcomes]
    with pytest.raises(ValueError, match="viewer may not read the logs topics"):
        subscriptions(Role.VIEWER, PREFIX, "logs")


def test_every_payload_named_in_the_table_exists() -> None:
    for topic in TOPICS:
        found = re.fullmatch(r"(.+) \((\w+/\w+)\.py\)", topic.payload)
        if topic.per_client:
            continue
        assert found, topic.payload
        module = importlib.import_module(found.group(2).replace("/", "."))
        for name in found.group(1).split(" or "):
            assert isinstance(getattr(module, name, None), type), (topic.key, name)


def test_the_docs_page_is_the_table() -> None:
    committed = (ROOT / "docs" / "reference" / "topics.md").read_text(encoding="utf-8")
    assert committed == topics_page(), (
        "docs/reference/topics.md is stale: python -m robotconf.workstation.docs"
    )
    for topic in TOPICS:
        shown = topic.pattern.replace("{robot}", "<id>").replace("{client}", "<client>")
        assert f"`<prefix>/{shown}`" in committed
