"""Every logger of the project is under `robotconf`, so that one name configures them all."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
PACKAGES = ["contract", "configurator", "readmodel", "reconciler", "workstation", "agent"]
# Other libraries' loggers, configured by their own names (quietened, mostly).
THIRD_PARTY = {"watchfiles", "amqtt", "transitions"}
# `logging.getLogger()` without a name is the root logger: only for attaching a handler.
ROOT_LOGGER_USERS = {"contract/lifecycle.py"}


def _is_get_logger(node: ast.AST) -> bool:
    if not isinstance(node, ast.Call):
        return False
    func = node.func
    return (isinstance(func, ast.Name) and func.id == "getLogger") or (
        isinstance(func, ast.Attribute) and func.attr == "getLogger"
    )


def _get_logger_calls(tree: ast.AST) -> list[ast.Call]:
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call) and _is_get_logger(node)]


def _sources() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def _problem(path: Path, call: ast.Call) -> str | None:
    where = f"{path.relative_to(ROOT)}:{call.lineno}"
    if not call.args and not call.keywords:
        if str(path.relative_to(ROOT)) in ROOT_LOGGER_USERS:
            return None
        return f"{where}: the root logger; log to a 'robotconf.*' logger"
    arg = call.args[0] if call.args else call.keywords[0].value
    if not (isinstance(arg, ast.Constant) and isinstance(arg.value, str)):
        return f"{where}: the logger's name must be a literal 'robotconf.*' (not __name__)"
    name = arg.value
    if name == "robotconf" or name.startswith("robotconf.") or name in THIRD_PARTY:
        return None
    return f"{where}: logger {name!r} is not under 'robotconf'"


def test_every_logger_is_named_under_robotconf() -> None:
    found = [
        (path, call)
        for path in _sources()
        for call in _get_logger_calls(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert len(found) >= 5  # the scan sees the project's loggers
    problems = [p for path, call in found if (p := _problem(path, call)) is not None]
    assert problems == []


@pytest.mark.parametrize(
    ("source", "ok"),
    [
        ('log = logging.getLogger("robotconf.agent")', True),
        ('logging.getLogger("amqtt").setLevel(logging.ERROR)', True),
        ("log = logging.getLogger(__name__)", False),
        ('log = getLogger("agent.process")', False),
        ("root = logging.getLogger()", False),
    ],
)
def test_the_check_tells_good_names_from_bad(source: str, ok: bool) -> None:
    module = ROOT / "agent" / "probe.py"  # a name for the message only: nothing is written
    calls = _get_logger_calls(ast.parse(source))
    assert len(calls) == 1
    assert (_problem(module, calls[0]) is None) is ok


def test_every_log_handler_escapes_what_peers_wrote() -> None:
    """Log lines quote robots' and peers' text: each handler the project sets up formats with
    `contract.logsafe.SafeFormatter`, never a plain `logging.Formatter`."""
    plain = [
        f"{path.relative_to(ROOT)}:{node.lineno}"
        for path in _sources()
        if path.name != "logsafe.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Attribute)
        and node.func.attr == "Formatter"
    ]
    assert plain == [], f"use SafeFormatter: {plain}"


def test_a_command_without_logging_of_its_own_escapes_stray_records(
    capsys: pytest.CaptureFixture[str],
) -> None:
    import logging

    from robotconf.contract.logsafe import escape_stray_records

    before = logging.lastResort
    try:
        escape_stray_records()
        record = logging.makeLogRecord(
            {"msg": "from %s", "args": ("tb3-01\nERROR forged\x1b[2J",), "levelno": 40}
        )
        assert logging.lastResort is not None
        logging.lastResort.handle(record)  # what logging does when no handler is set up
    finally:
        logging.lastResort = before
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "\x1b" not in err and "forged" in err
