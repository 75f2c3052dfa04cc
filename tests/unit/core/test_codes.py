"""The registry of diagnostic codes: the code uses exactly what it declares, the docs show it."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from robotconf.configurator.rules.report import Reporter
from robotconf.contract.codes import (
    RULES,
    Severity,
    UnregisteredCode,
    readme_table,
    with_readme_table,
)
from robotconf.contract.diagnostics import Diagnostic
from robotconf.contract.yamlio import YamlProblem, parse_document
from tests.support.lab import ROOT

CODE = re.compile(r"\bRC\d{3}\b")
REGISTRY = ROOT / "contract" / "codes.py"
PAGE = ROOT / "docs" / "reference" / "rules.md"
UPDATE = "python -m robotconf.workstation.docs"


def _sources() -> list[Path]:
    found = [
        path
        for package in (
            "contract",
            "configurator",
            "readmodel",
            "reconciler",
            "workstation",
            "agent",
        )
        for path in sorted((ROOT / package).rglob("*.py"))
        if path != REGISTRY
    ]
    assert len(found) > 30, "the packages were not found"
    return found


def test_every_code_named_in_the_packages_is_declared() -> None:
    # Comments and messages too: a code named anywhere is one a reader will look up.
    undeclared = [
        f"{path.relative_to(ROOT)}:{number}: {code}"
        for path in _sources()
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        for code in CODE.findall(line)
        if code not in RULES
    ]
    assert not undeclared, "declare these in contract/codes.py:\n" + "\n".join(undeclared)


def test_every_declared_code_is_used_as_a_literal() -> None:
    used = {
        node.value
        for path in _sources()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and CODE.fullmatch(node.value)
    }
    dead = sorted(set(RULES) - used)
    assert not dead, f"declared in contract/codes.py but never reported: {dead}"
    assert used <= set(RULES)


def _stale_rows(text: str) -> list[str]:
    table = text[text.index("| code | rule |") :].split("\n\n", 1)[0] + "\n"
    return sorted(set(table.splitlines()) ^ set(readme_table().splitlines()))


def test_the_docs_table_is_generated_from_the_registry() -> None:
    page = PAGE.read_text(encoding="utf-8")
    if with_readme_table(page) != page:
        pytest.fail(
            "docs/reference/rules.md's table of rule codes is not contract/codes.py's; after "
            f"editing the registry, run `{UPDATE}`. Rows that differ:\n"
            + "\n".join(_stale_rows(page))
        )


def test_a_readme_table_if_any_is_generated_too() -> None:
    # The README links to the docs page; a copy of the table left there must not go stale.
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    if "| code | rule | tunable |" in readme and with_readme_table(readme) != readme:
        pytest.fail(
            "README.md's table of rule codes is stale: "
            "run `python -m robotconf.contract.codes README.md` "
            "(or drop it and link docs/reference/rules.md). Rows that differ:\n"
            + "\n".join(_stale_rows(readme))
        )


def test_a_text_without_the_table_is_refused_with_its_head_named() -> None:
    with pytest.raises(
        ValueError, match=r"no table of rule codes: .*\| code \| rule \| tunable \|"
    ):
        with_readme_table("# Rule codes\n\nnothing here\n")


def test_the_table_is_rewritten_row_for_row() -> None:
    current = with_readme_table(PAGE.read_text(encoding="utf-8"))
    row = f"| RC204 | {RULES['RC204'].summary} | no: {RULES['RC204'].fixed} |\n"
    assert row in current
    edited = current.replace(row, "| RC204 | something else | yes |\n| RC999 | invented |\n")
    assert with_readme_table(edited) == current
    assert with_readme_table(current.replace(row, "")) == current
    assert f"| RC608 | warning: {RULES['RC608'].summary} | yes |\n" in current


def test_registry_declares_each_code_once_with_a_summary() -> None:
    for code, rule in RULES.items():
        assert rule.code == code and CODE.fullmatch(code)
        assert rule.summary and "|" not in rule.summary and "\n" not in rule.summary
    warnings = [c for c, r in RULES.items() if r.severity is Severity.WARNING]
    assert warnings == ["RC608", "RC706", "RC802", "RC803"]


def test_rules_that_can_make_a_robot_unsafe_or_undeliverable_cannot_be_tuned() -> None:
    tunable = [code for code, rule in RULES.items() if rule.tunable]
    lab_judgement = ["RC505", "RC605", "RC607", "RC608", "RC703", "RC704", "RC706"]
    assert tunable == [*lab_judgement, "RC802", "RC803"]
    for code, rule in RULES.items():
        assert "|" not in rule.fixed and "\n" not in rule.fixed, code


def test_a_diagnostic_with_an_undeclared_code_is_refused() -> None:
    with pytest.raises(UnregisteredCode, match="'RC999' is not declared"):
        Diagnostic("configs/fleet.yaml", 1, 1, Severity.ERROR, "RC999", "invented")
    with pytest.raises(UnregisteredCode, match="RC501 is declared as error, not warning"):
        Diagnostic("configs/fleet.yaml", 1, 1, Severity.WARNING, "RC501", "wrong severity")
    # A rule a lab can tune comes at the severity `.robotconf.yaml` gives it.
    assert Diagnostic("a.yaml", 1, 1, Severity.ERROR, "RC608", "tuned").is_error
    with pytest.raises(UnregisteredCode):
        YamlProblem(1, 1, "RC010", "invented")
    assert Diagnostic("a.yaml", 1, 1, Severity.WARNING, "RC608", "fine").code == "RC608"


def test_the_reporter_takes_the_severity_from_the_registry() -> None:
    from robotconf.configurator.repository import Entry
    from robotconf.configurator.types import Task

    doc = parse_document("models/tasks/Deliver.yaml", b"implementations: [[Go]]\n")
    entry = Entry("Deliver", Task.model_validate(doc.data), doc)
    report = Reporter()
    report.add(entry, ["implementations", 0], "RC608", "a warning by declaration")
    report.add(entry, ["implementations", 0, 0], "RC603", "an error by declaration")
    assert [(d.severity, d.line, d.col) for d in report.found] == [
        (Severity.WARNING, 1, 19),
        (Severity.ERROR, 1, 20),
    ]
    with pytest.raises(UnregisteredCode):
        report.add(entry, [], "RC699", "invented")
    report.unknown(entry, [], "RC603", "unknown action 'Goo'", "Goo", ["Go"], unreadable=True)
    assert len(report.found) == 2
    report.unknown(entry, [], "RC603", "unknown action 'Goo'", "Goo", ["Go"])
    assert report.found[-1].message == "unknown action 'Goo'; did you mean 'Go'?"
