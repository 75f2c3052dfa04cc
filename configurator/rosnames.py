"""ROS 2 names: a robot's namespace and a mapping's name checked by the ROS 2 naming rules,
and a mapping name resolved to the fully qualified name one robot uses. Pure."""

from __future__ import annotations

import functools
import re

# The rules are the design article "Topic and Service name mapping to DDS": a token is
# letters, digits and single underscores, does not start with a digit and does not end with
# an underscore (`a_/b` would be `a___b` in DDS, as `a/_b` is). rcl accepts some names the
# article refuses (`a__b`); a name valid here is valid in every ROS 2 distribution.
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
NAMESPACE_SUBSTITUTION = "{namespace}"
# DDS limits topic names to 255 characters; ROS 2 keeps 8 for its prefix (`rt`, `rq`, ...) and
# one per token for the `/` each becomes: C + N + 8 <= 255 for a fully qualified name.
_DDS_LIMIT = 255
_PREFIX_RESERVE = 8
# What a fully qualified name may cost (`name_cost`) within that limit.
NAME_BUDGET = _DDS_LIMIT - _PREFIX_RESERVE


class UnresolvableName(ValueError):
    """A mapping name that cannot be resolved for a robot (it needs the robot's namespace)."""


def _token_problem(token: str) -> str | None:
    if token == "":
        return "has an empty token ('//', or a '/' at the end)"
    if token[0].isdigit():
        return f"has token '{token}' starting with a digit"
    if _TOKEN.fullmatch(token) is None:
        bad = sorted({c for c in token if not (c.isascii() and (c.isalnum() or c == "_"))})
        chars = ", ".join(repr(c) for c in bad)
        return f"has token '{token}' with {chars}: use letters, digits, '_'"
    if "__" in token:
        return f"has token '{token}' with a repeated underscore"
    if token.endswith("_"):
        return f"has token '{token}' ending with an underscore"
    return None


def _tokens_problem(tokens: list[str]) -> str | None:
    for token in tokens:
        problem = _token_problem(token)
        if problem is not None:
            return problem
    return None


def name_cost(name: str) -> int:
    """A name's characters and tokens (one per '/'): what DDS's limit counts."""
    return len(name) + name.count("/")


def length_problem(full_name: str) -> str | None:
    """Why a fully qualified name is too long for DDS, or None."""
    tokens = full_name.count("/")
    if len(full_name) + tokens + _PREFIX_RESERVE > _DDS_LIMIT:
        limit = _DDS_LIMIT - _PREFIX_RESERVE
        return (
            f"is too long for DDS: '{full_name}' has {len(full_name)} characters and {tokens} "
            f"tokens, together at most {limit}"
        )
    return None


def namespace_problem(namespace: str) -> str | None:
    """Why `namespace` is not a robot's ROS 2 namespace, or None. `tb3_01` and `/tb3_01` are
    the same namespace (a relative one is made absolute, as rclcpp does); the root namespace
    `/` is no namespace, so it is left out instead of written."""
    if namespace == "":
        return "is empty; leave `namespace` out for none"
    if namespace == "/":
        return "'/' is the root namespace, which every robot has: leave `namespace` out"
    if namespace.startswith("~") or "{" in namespace or "}" in namespace:
        return "is a namespace, not a name to expand: no '~' and no '{...}'"
    body = namespace[1:] if namespace.startswith("/") else namespace
    problem = _tokens_problem(body.split("/"))
    if problem is not None:
        return problem
    return length_problem(absolute_namespace(namespace))


def absolute_namespace(namespace: str) -> str:
    """A valid namespace written absolute: `tb3_01` -> `/tb3_01`."""
    return namespace if namespace.startswith("/") else "/" + namespace


def suggest_namespace(text: str) -> str:
    """A valid namespace near `text` for a did-you-mean: `tb3-01` -> `tb3_01`."""
    tokens = []
    for raw in text.replace("\\", "/").split("/"):
        token = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", raw)).strip("_")
        if token:
            tokens.append("_" + token if token[0].isdigit() else token)
    return "/".join(tokens) or "robot"


# A lab has a few hundred mapping names, asked about for each scenario that binds them.
@functools.lru_cache(maxsize=4096)
def mapping_name_problem(name: str) -> str | None:
    """Why `name` is not a mapping name, or None. A mapping name is a ROS 2 topic, service or
    action name: absolute (`/cmd_vel`), relative (`cmd_vel`, resolved in the robot's
    namespace) or starting with `{namespace}` (the robot's namespace; the robot must have one).
    A private name (`~/x`) is refused: it depends on the brain's node name, which no
    configuration knows; so is any other substitution."""
    if name == "":
        return "is empty"
    if name.startswith("~"):
        return "is private ('~'): it depends on the brain's node name; use a relative name"
    if name == "/":
        return "is the root namespace, not a name"
    rest = name
    if name.startswith(NAMESPACE_SUBSTITUTION):
        rest = name[len(NAMESPACE_SUBSTITUTION) :]
        if rest == "":
            return f"is only {NAMESPACE_SUBSTITUTION}: add a name, e.g. {{namespace}}/cmd_vel"
        if not rest.startswith("/"):
            return f"must continue with '/' after {NAMESPACE_SUBSTITUTION}"
    if "{" in rest or "}" in rest:
        return f"has a substitution other than a leading {NAMESPACE_SUBSTITUTION}"
    if rest.startswith("/"):
        rest = rest[1:]
    problem = _tokens_problem(rest.split("/"))
    if problem is not None:
        return problem
    if not name.startswith(NAMESPACE_SUBSTITUTION):
        return length_problem(name if name.startswith("/") else "/" + name)
    return None


def needs_namespace(name: str) -> bool:
    return name.startswith(NAMESPACE_SUBSTITUTION)


def resolve_name(name: str, namespace: str | None) -> str:
    """The fully qualified name a valid mapping name has for a robot with `namespace` (valid,
    or None). Absolute stays; relative goes into the namespace (the root without one);
    `{namespace}` becomes the namespace, and without one raises UnresolvableName: a scheme
    writes it to say its names are per robot, and putting them at the root would make every
    robot without a namespace share them."""
    return resolve_in(name, None if namespace is None else absolute_namespace(namespace))


def resolve_in(name: str, absolute: str | None) -> str:
    """`resolve_name` in a namespace written absolute already (or None)."""
    if needs_namespace(name):
        if absolute is None:
            raise UnresolvableName(f"'{name}' needs the robot's namespace, and it has none")
        return absolute + name[len(NAMESPACE_SUBSTITUTION) :]
    if name.startswith("/"):
        return name
    if absolute is None:
        return "/" + name
    return absolute + "/" + name
