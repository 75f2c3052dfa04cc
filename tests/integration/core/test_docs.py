"""The docs site: its reference pages are what the code generates, and it builds with warnings
as errors (a broken link or a page missing from the nav fails the build)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from robotconf.workstation import docs
from tests.support.lab import ROOT

FIX = "run `python -m robotconf.workstation.docs` and commit the pages"


def test_the_reference_pages_are_what_the_code_generates() -> None:
    stale = [page for page, (now, new) in docs.wanted(ROOT).items() if now != new]
    assert not stale, f"stale: {stale}; {FIX}"


def _copy_site(tmp_path: Path) -> Path:
    site = tmp_path / "repo"
    shutil.copytree(ROOT / "docs", site / "docs")
    shutil.copy(ROOT / "mkdocs.yml", site / "mkdocs.yml")
    return site


def test_check_names_the_stale_page_and_writing_makes_it_current(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _copy_site(tmp_path)
    assert docs.main(["--check", "--root", str(root)]) == 0
    commands = root / "docs/reference/commands.md"
    commands.write_text(commands.read_text(encoding="utf-8") + "\nedited by hand\n")
    capsys.readouterr()
    assert docs.main(["--check", "--root", str(root)]) == 1
    err = capsys.readouterr().err
    assert "stale: docs/reference/commands.md; run: python -m robotconf.workstation.docs" in err
    assert "rules.md" not in err
    assert docs.main(["--root", str(root)]) == 0
    assert docs.main(["--check", "--root", str(root)]) == 0


def test_a_page_without_what_the_generator_fills_in_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _copy_site(tmp_path)
    (root / "docs/reference/rules.md").write_text("# Rule codes\n\nno table\n")
    assert docs.main(["--check", "--root", str(root)]) == 2
    assert "docs/reference/rules.md: no table of rule codes" in capsys.readouterr().err
    (root / "docs/reference/rules.md").write_bytes((ROOT / "docs/reference/rules.md").read_bytes())
    formats = root / "docs/reference/file-formats.md"
    formats.write_text(formats.read_text().replace("<!-- generated: task -->", ""))
    assert docs.main(["--check", "--root", str(root)]) == 2
    err = capsys.readouterr().err
    assert "docs/reference/file-formats.md: each of task needs exactly one block" in err
    assert docs.main(["--root", str(tmp_path / "nowhere")]) == 2
    assert "has no docs/ folder" in capsys.readouterr().err


def test_every_command_is_on_the_page_with_its_own_help() -> None:
    page = (ROOT / "docs/reference/commands.md").read_text(encoding="utf-8")
    paths = docs.command_paths()
    assert len(paths) >= 15 and ["validate"] in paths and ["agent"] in paths
    for words in paths:
        assert f"## `robotconf {' '.join(words)}`" in page
    # The agent's help is argparse's, from agent/cli.py, not click's stub.
    assert "usage: robotconf agent [-h] --config PATH" in docs.command_help(["agent"])


def test_help_on_the_page_does_not_depend_on_the_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")
    wide = docs.command_help(["reconcile"]), docs.command_help(["agent"])
    monkeypatch.setenv("COLUMNS", "50")
    # Colour forced (click, Python 3.14's argparse) never reaches the page.
    for name in ("FORCE_COLOR", "CLICOLOR_FORCE", "PYTHON_COLORS"):
        monkeypatch.setenv(name, "1")
    monkeypatch.delenv("NO_COLOR", raising=False)
    narrow = docs.command_help(["reconcile"]), docs.command_help(["agent"])
    assert wide == narrow
    assert max(len(line) for text in wide for line in text.splitlines()) <= 80


def test_every_schema_has_its_format_on_the_page() -> None:
    page = (ROOT / "docs/reference/file-formats.md").read_text(encoding="utf-8")
    for schema in sorted((ROOT / "schemas").glob("*.schema.json")):
        assert f"Schema: `schemas/{schema.name}`" in page, schema.name
    for title in ("Logic", "agent.yaml", "Launch Request", "Rule configuration"):
        assert f"## {title} {{#" in page or f"### {title} {{#" in page, title


def test_generated_blocks_are_rewritten_and_the_text_around_them_kept() -> None:
    text = "# Page\n\nby hand\n\n<!-- generated: a -->\nold\n<!-- end generated -->\n\nafter\n"
    done = docs.splice(text, {"a": "| new |\n"})
    assert done == text.replace("old\n", "\n| new |\n\n")
    assert docs.splice(done, {"a": "| new |\n"}) == done
    with pytest.raises(ValueError, match="each of b needs exactly one block"):
        docs.splice(text, {"a": "", "b": ""})
    with pytest.raises(ValueError, match="no such generated block: a"):
        docs.splice(text, {})
    with pytest.raises(ValueError, match="the block a has no `<!-- end generated -->`"):
        docs.splice("<!-- generated: a -->\nold\n", {"a": ""})


def _build(site: Path) -> subprocess.CompletedProcess[str]:
    # Not --quiet: it drops the warnings that --strict counts, and the build passes.
    command = [sys.executable, "-m", "mkdocs", "build", "--strict"]
    command += ["-f", str(site / "mkdocs.yml"), "-d", str(site / "site")]
    return subprocess.run(command, capture_output=True, text=True, timeout=300)


def test_the_site_builds_and_a_broken_link_or_anchor_or_a_missing_page_fails_it(
    tmp_path: Path,
) -> None:
    good = _build(_copy_site(tmp_path / "good"))
    assert good.returncode == 0, good.stderr
    broken = _copy_site(tmp_path / "broken")
    with (broken / "docs/index.md").open("a", encoding="utf-8") as page:
        page.write("\nSee [the missing page](how-to/no-such-page.md).\n")
    done = _build(broken)
    assert done.returncode != 0
    assert "no-such-page.md" in done.stderr
    anchor = _copy_site(tmp_path / "anchor")
    with (anchor / "docs/index.md").open("a", encoding="utf-8") as page:
        page.write("\nSee [a code](reference/rules.md#no-such-anchor).\n")
    done = _build(anchor)
    assert done.returncode != 0
    assert "no-such-anchor" in done.stderr
    missing = _copy_site(tmp_path / "missing")
    (missing / "docs/how-to/desk.md").unlink()
    done = _build(missing)
    assert done.returncode != 0
    assert "how-to/desk.md" in done.stderr
