"""The docs site's reference pages generated from the code: every command's `--help`, the rule
codes table, the file formats' fields and the MQTT topic table;
`python -m robotconf.workstation.docs [--check]` writes or checks them (rules.md and
file-formats.md are hand-written around their generated tables).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
from pydantic import BaseModel

from robotconf.contract.codes import with_readme_table
from robotconf.contract.errors import ExitCode
from robotconf.contract.topics import CLIENT, EVERYONE, ROBOT, TOPICS, Role, Topic

ROOT = Path(__file__).resolve().parents[1]
# Help is laid out for an 80-column terminal whatever the terminal generating it is.
COLUMNS = "80"
COMMAND = "python -m robotconf.workstation.docs"
GENERATED = f"Generated from the code by `{COMMAND}`: edit the code, not this page."


# ---- commands.md -------------------------------------------------------------------------


# Everything in the environment that changes what `--help` prints, across the Pythons the
# project supports (3.10-3.13: argparse reads COLUMNS through shutil.get_terminal_size; 3.14's
# argparse colours help unless PYTHON_COLORS=0 or NO_COLOR) and click's versions (COLUMNS;
# colour only when forced). Help generated under 3.10.13, 3.12.1 and 3.13.0 with click 8.1.8
# and 8.5.1 is the same page.
FIXED = {"COLUMNS": COLUMNS, "NO_COLOR": "1", "PYTHON_COLORS": "0"}
UNSET = ("FORCE_COLOR", "CLICOLOR_FORCE", "LINES")


@contextlib.contextmanager
def _fixed_terminal() -> Iterator[None]:
    """The help laid out the same whatever the terminal and environment generating it."""
    saved = {name: os.environ.get(name) for name in (*FIXED, *UNSET)}
    os.environ.update(FIXED)
    for name in UNSET:
        os.environ.pop(name, None)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def command_help(words: list[str]) -> str:
    """What `robotconf WORDS --help` prints, taken from the same entry point the shell runs
    (so `robotconf agent --help` is the agent's argparse help)."""
    from robotconf.workstation.cli.main import main

    out = io.StringIO()
    with _fixed_terminal(), contextlib.redirect_stdout(out):
        code = main([*words, "--help"])
    if code != ExitCode.OK:
        raise RuntimeError(f"robotconf {' '.join(words)} --help exited {code}")
    return out.getvalue()


def command_paths() -> list[list[str]]:
    """Every command and subcommand, depth first in the order `robotconf --help` lists them."""
    from robotconf.workstation.cli.main import cli

    found: list[list[str]] = []

    def walk(group: click.Group, ctx: click.Context, words: list[str]) -> None:
        for name in group.list_commands(ctx):
            command = group.get_command(ctx, name)
            found.append([*words, name])
            if isinstance(command, click.Group):
                walk(command, click.Context(command, info_name=name, parent=ctx), [*words, name])

    walk(cli, click.Context(cli, info_name="robotconf"), [])
    return found


INTRO = """\
Every failure is one line on stderr, `robotconf: <what went wrong>`, never a traceback. Exit
codes: 0 done; 1 what was checked is wrong (errors from `validate`, a stale file under
`--check`, a fleet not all in sync for `status`, a robot that did not answer `logs` or
`restart`); 2 the tool could not do its job (a usage error, no such repository or revision, a
broker it cannot reach); 130 after Ctrl-C. Set `ROBOTCONF_DEBUG=1` to see a traceback instead
of the one-line internal-error message.

`--repo DIR` (default: the current folder) wherever a repository is read, `--rev REV` to read
a commit instead of the work tree. `--broker URL` (`mqtt://host:port`, `mqtts://` for TLS;
default `$ROBOTCONF_BROKER`, else for `status`, `logs`, `restart`, `rollout`, `promote`,
`plan`, `draft` and `autofill --robot` the broker of a `robotconf up` running in the repository,
with its login and key, else `mqtt://127.0.0.1:1883`) and `--prefix` (default `robotconf`)
wherever MQTT is used. A broker that is not there is said at once, in one line naming its URL
and what to do: nothing listening on the port (`cannot connect to the broker at URL (connection
refused: nothing listens on that port): is the broker running? ...`), a connection reset or
closed before the broker answered (plain MQTT to a TLS listener, or the reverse), a failed TLS
handshake, an unknown host, a refused login. Only a network that stays silent is waited out
(`--wait`).
"""


def commands_page() -> str:
    parts = [
        "# Commands\n\n",
        f"{GENERATED} Each section is what `--help` prints.\n\n",
        INTRO,
    ]
    for words in [[], *command_paths()]:
        name = " ".join(["robotconf", *words])
        anchor = "-".join(["robotconf", *words])
        parts.append(f"\n## `{name}` {{#{anchor}}}\n\n```text\n{command_help(words)}```\n")
    return "".join(parts)


# ---- file-formats.md ---------------------------------------------------------------------


@dataclass(frozen=True)
class Format:
    """One document format: its anchor, title, where it lives, its type and its schema file."""

    anchor: str
    title: str
    place: str
    model: type[BaseModel]
    schema: str | None


def _place(pattern: re.Pattern[str]) -> str:
    """A loader path pattern as a reader writes it: `models/actions/<name>.yaml`."""
    text = pattern.pattern.strip("^$").replace("platforms/([^/]+)", "platforms/<platform>")
    text = text.replace("([^/]+)", "<name>")
    return re.sub(r"\((\w+)\)", r"\1", text).replace("\\", "")


def formats() -> list[Format]:
    """Every document format, the catalogue's first, then the lab's, then the others."""
    from robotconf.agent.config import AgentConfig
    from robotconf.configurator.loader import KIND_BY_NAME, RULE_CONFIGURATION_KIND
    from robotconf.contract.launch import LaunchRequest

    catalogue = ["platform", "robot-template", "mapping-scheme", "action", "task", "environment"]
    order = [*catalogue, "capability", "scenario", "fleet"]
    found = [
        Format(name, kind.title.capitalize(), f"`{_place(kind.pattern)}`", kind.model, name)
        for name, kind in ((n, KIND_BY_NAME[n]) for n in order)
    ]
    rules = RULE_CONFIGURATION_KIND
    return [
        *found,
        Format(
            "rule-configuration",
            "Rule configuration",
            f"`{_place(rules.pattern)}` at the repository root ([Rule codes](rules.md))",
            rules.model,
            "rule-configuration",
        ),
        Format(
            "agent-yaml",
            "agent.yaml",
            "on the robot, given to `robotconf agent --config PATH`",
            AgentConfig,
            None,
        ),
        Format(
            "launch-request",
            "Launch Request",
            "rendered per robot (`robotconf render`), delivered by the reconciler over MQTT",
            LaunchRequest,
            "launch-request",
        ),
    ]


def _cell(text: str) -> str:
    """Text safe in a table cell: one line; outside code spans no HTML tag and no column break
    (Python-Markdown's tables keep a code span's `|` and `<` as they are)."""
    pieces = " ".join(text.split()).split("`")
    for index in range(0, len(pieces), 2):  # the even pieces are outside code spans
        for raw, safe in (("<", "&lt;"), ("|", "\\|"), ("*", "\\*"), ("_", "\\_")):
            pieces[index] = pieces[index].replace(raw, safe)
    return "`".join(pieces)


def _code(value: object) -> str:
    """A JSON value as a code span."""
    text = json.dumps(value, ensure_ascii=False)
    return f"`` {text} ``" if "`" in text else f"`{text}`"


LIMITS = {
    "minimum": "≥ {}",
    "exclusiveMinimum": "> {}",
    "maximum": "≤ {}",
    "exclusiveMaximum": "< {}",
    "minLength": "at least {} characters",
    "maxLength": "at most {} characters",
    "minItems": "at least {} items",
    "maxItems": "at most {} items",
    "minProperties": "at least {} entries",
    "maxProperties": "at most {} entries",
    "pattern": "matching {}",
}


def _limits(schema: dict[str, Any]) -> str:
    if schema.get("minItems") == 1 or schema.get("minProperties") == 1:
        schema = {k: v for k, v in schema.items() if k not in ("minItems", "minProperties")}
        return _limits(schema)[:-1] + ", not empty)" if _limits(schema) else " (not empty)"
    words = [
        text.format(_code(schema[key]) if key == "pattern" else schema[key])
        for key, text in LIMITS.items()
        if key in schema
    ]
    if schema.get("uniqueItems"):
        words.append("each once")
    return f" ({', '.join(words)})" if words else ""


def _type(schema: dict[str, Any], link: Callable[[str], str]) -> str:
    """A schema's type in words; a nested object type is a link to its own table."""
    if "$ref" in schema:
        return link(schema["$ref"].rsplit("/", 1)[1]) + _limits(schema)
    if "allOf" in schema and len(schema["allOf"]) == 1:
        return _type(schema["allOf"][0], link)
    if "anyOf" in schema or "oneOf" in schema:
        branches = schema.get("anyOf") or schema["oneOf"]
        return " or ".join(_type(branch, link) for branch in branches) + _limits(schema)
    if "const" in schema:
        return _code(schema["const"])
    if "enum" in schema:
        return "one of " + ", ".join(_code(value) for value in schema["enum"])
    kind = schema.get("type", "any")
    if isinstance(kind, list):
        return " or ".join(kind) + _limits(schema)
    if kind == "array":
        items = _type(schema.get("items", {}), link)
        items = f"({items})" if " or " in items else items
        return f"list of {items}{_limits(schema)}"
    extra = schema.get("additionalProperties")
    if kind == "object" and isinstance(extra, dict) and "properties" not in schema:
        key = schema.get("propertyNames", {})
        keys = "name" + _limits(key) if key else "name"
        value = _type(extra, link)
        value = f"({value})" if " or " in value else value
        return f"map of {keys} to {value}{_limits(schema)}"
    return str(kind) + _limits(schema)


def _about(field: dict[str, Any], defs: dict[str, Any]) -> str:
    """A field's description; a field of a nested type without one has the type's own."""
    if "description" in field:
        return str(field["description"])
    refs = [b["$ref"] for b in [field, *field.get("anyOf", [])] if "$ref" in b]
    if len(refs) == 1:
        return str(defs.get(refs[0].rsplit("/", 1)[1], {}).get("description", ""))
    return ""


def _fields_table(schema: dict[str, Any], link: Callable[[str], str], defs: dict[str, Any]) -> str:
    properties: dict[str, dict[str, Any]] = schema.get("properties", {})
    if not properties:
        return "No fields of its own.\n"
    required = set(schema.get("required", []))
    rows = [
        "| field | type | required | default | description |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name, field in properties.items():
        default = _code(field["default"]) if "default" in field else ""
        about = _cell(_about(field, defs))
        needed = "yes" if name in required else "no"
        rows.append(f"| `{name}` | {_type(field, link)} | {needed} | {default} | {about} |")
    closed = schema.get("additionalProperties") is False
    note = "\nNo other field is accepted.\n" if closed else ""
    return "\n".join(rows) + "\n" + note


def _defs_in_order(schema: dict[str, Any]) -> list[str]:
    """The nested types a schema uses, in the order a reader meets them."""
    defs = schema.get("$defs", {})
    seen: list[str] = []

    def visit(node: object) -> None:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                name = ref.rsplit("/", 1)[1]
                if name not in seen:
                    seen.append(name)
                    visit(defs.get(name, {}))
            for key, value in node.items():
                if key != "$defs":
                    visit(value)
        elif isinstance(node, list):
            for item in node:
                visit(item)

    visit(schema)
    return seen


def format_fields(fmt: Format) -> str:
    """Where a format's files live, its schema, and a table of its fields and of each nested
    type's (under a heading of its own, linked from the field that uses it)."""
    schema = fmt.model.model_json_schema()

    def link(name: str) -> str:
        return f"[{name}](#{fmt.anchor}-{name.lower()})"

    where = f"Where: {fmt.place}."
    if fmt.schema:
        where += f" Schema: `schemas/{fmt.schema}.schema.json`."
    parts = [where + "\n\n"]
    if schema.get("description"):
        parts.append(_cell(schema["description"]) + "\n\n")
    defs = schema.get("$defs", {})
    parts.append(_fields_table(schema, link, defs))
    for name in _defs_in_order(schema):
        nested = schema["$defs"][name]
        parts.append(f"\n### {name} {{#{fmt.anchor}-{name.lower()}}}\n\n")
        parts.append(f"In {fmt.title}.")
        if nested.get("description"):
            parts.append(" " + _cell(nested["description"]))
        parts.append("\n\n")
        if "properties" in nested:
            parts.append(_fields_table(nested, link, defs))
        else:
            parts.append(f"Type: {_type(nested, link)}.\n")
    return "".join(parts)


MARK = "<!-- generated: {} -->\n"
END = "<!-- end generated -->\n"


def splice(text: str, blocks: dict[str, str]) -> str:
    """The text with each `<!-- generated: NAME -->` ... `<!-- end generated -->` block
    written anew: the hand-written text around the blocks stays as it is."""
    named = re.findall(r"<!-- generated: (\S+) -->", text)
    missing = [name for name in blocks if named.count(name) != 1]
    unknown = sorted(set(named) - set(blocks))
    if missing:
        raise ValueError(
            f"each of {', '.join(missing)} needs exactly one block "
            f"`{MARK.format('NAME').strip()}` ... `{END.strip()}`"
        )
    if unknown:
        raise ValueError(f"no such generated block: {', '.join(unknown)}")
    for name, block in blocks.items():
        start = text.index(MARK.format(name)) + len(MARK.format(name))
        end = text.find(END, start)
        if end < 0:
            raise ValueError(f"the block {name} has no `{END.strip()}` after it")
        # Blank lines around the block: Markdown reads a comment line as an HTML block.
        text = text[:start] + "\n" + block.rstrip("\n") + "\n\n" + text[end:]
    return text


def file_formats_page(current: str) -> str:
    """file-formats.md is written by hand around its blocks; the field tables are generated."""
    every = formats()
    table = "| format | where |\n| --- | --- |\n"
    table += "".join(f"| [{f.title}](#{f.anchor}) | {f.place} |\n" for f in every)
    return splice(current, {"formats": table} | {f.anchor: format_fields(f) for f in every})


# ---- topics.md ---------------------------------------------------------------------------

TOPICS_HEAD = """# MQTT topics

Every topic the project uses, under the prefix (`robotconf` unless agent.yaml and the
reconciler's `--prefix` say otherwise). `<id>` is a robot's id: a robot may use only its own;
`<client>` is a client's id. Generated from `contract/topics.py`, the one declaration the
broker ACL (`robotconf broker-config`), the agent's and the reconciler's subscriptions and the
checks of `robotconf up`'s embedded broker are derived from: rewrite this page with
`python -m robotconf.workstation.docs`.

"""
TOPICS_TABLE_HEAD = (
    "| topic | from → to | payload | read by | written by | retained | QoS | what |\n"
    "| --- | --- | --- | --- | --- | --- | --- | --- |\n"
)
TOPICS_TAIL = """
Roles: **robot** is a robot's agent, logged in with its robot id (own topics only);
**reconciler**, **viewer** (`robotconf status`) and **operator** (`robotconf logs`,
`robotconf restart`, the desk) are the service users. Whatever no role is given is denied, by
Mosquitto (the generated ACL) and by `robotconf up`'s broker alike.
"""


def _topic_who(roles: frozenset[Role], topic: Topic) -> str:
    if topic.per_client:
        return "every client (own client id)" if roles == EVERYONE else "-"
    return ", ".join(
        role.value + (" (own id)" if role is Role.ROBOT else "") for role in Role if role in roles
    )


def _topic_row(topic: Topic) -> str:
    name = "<prefix>/" + topic.pattern.replace(ROBOT, "<id>").replace(CLIENT, "<client>")
    qos = "-" if topic.qos is None else str(topic.qos)
    cells = [
        f"`{name}`",
        topic.direction,
        topic.payload,
        _topic_who(topic.read, topic),
        _topic_who(topic.write, topic),
    ]
    cells += ["yes" if topic.retained else "no", qos, topic.about]
    return "| " + " | ".join(cells) + " |\n"


def topics_page() -> str:
    """docs/reference/topics.md, generated from TOPICS."""
    return TOPICS_HEAD + TOPICS_TABLE_HEAD + "".join(_topic_row(t) for t in TOPICS) + TOPICS_TAIL


# ---- the pages ---------------------------------------------------------------------------


def _rules_page(current: str) -> str:
    """rules.md is written by hand around its table; only the table is generated."""
    return with_readme_table(current)


PAGES: dict[str, Callable[[str], str]] = {
    "docs/reference/commands.md": lambda _current: commands_page(),
    "docs/reference/rules.md": _rules_page,
    "docs/reference/file-formats.md": file_formats_page,
    "docs/reference/topics.md": lambda _current: topics_page(),
}


def wanted(root: Path) -> dict[str, tuple[str, str]]:
    """Page -> (its text now, the text generated for it)."""
    found: dict[str, tuple[str, str]] = {}
    for page, generate in PAGES.items():
        path = root / page
        current = path.read_text(encoding="utf-8") if path.is_file() else ""
        try:
            found[page] = (current, generate(current))
        except ValueError as exc:  # a hand-written page lost what the generator fills in
            raise ValueError(f"{page}: {exc}") from None
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m robotconf.workstation.docs",
        description="Write the docs site's generated reference pages (commands, rule codes, "
        "file formats); --check fails when one is stale.",
    )
    parser.add_argument("--check", action="store_true", help="fail when a page is stale")
    parser.add_argument("--root", type=Path, default=ROOT, help="the repository (default: ours)")
    args = parser.parse_args(argv)
    if not (args.root / "docs").is_dir():
        print(f"{COMMAND}: {args.root} has no docs/ folder", file=sys.stderr)
        return ExitCode.TOOL
    try:
        pages = wanted(args.root)
    except (OSError, UnicodeDecodeError, ValueError, RuntimeError) as exc:
        print(f"python -m robotconf.workstation.docs: {exc}", file=sys.stderr)
        return ExitCode.TOOL
    stale = [page for page, (now, new) in pages.items() if now != new]
    if args.check:
        if stale:
            print(f"stale: {', '.join(stale)}; run: {COMMAND}", file=sys.stderr)
            return ExitCode.FINDINGS
        print(f"docs are current ({len(pages)} generated pages)")
        return ExitCode.OK
    for page in stale:
        (args.root / page).write_text(pages[page][1], encoding="utf-8")
    print(f"docs: {len(stale)} written, {len(pages) - len(stale)} unchanged")
    return ExitCode.OK


if __name__ == "__main__":
    raise SystemExit(main())
