"""Every pointer the code makes into the docs (`docs/<page>.md#<anchor>`) names a page and a
heading that exist, and no citation of a DESIGN file outside the repository is left."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

from tests.support.lab import ROOT

DOCS = ROOT / "docs"
POINTER = re.compile(r"(?<![\w/.-])docs/([\w/.-]*?\.md)(?:#([\w-]+))?")
# Written in two parts so that this file does not cite it.
DESIGN = "DESIGN " + "\N{SECTION SIGN}"
SCANNED_FOLDERS = (
    "contract",
    "configurator",
    "readmodel",
    "reconciler",
    "workstation",
    "agent",
    "bench",
    "tests",
)
SCANNED_FILES = ("README.md", "pyproject.toml", "dev", ".robotconf.yaml", ".ci/run")
HEADING = re.compile(r"^(#{1,6})\s+(.+?)(?:\s+#+)?\s*$")
EXPLICIT_ID = re.compile(r"\s*\{:?\s*#([\w-]+)[^}]*\}\s*$")
INLINE_LINK = re.compile(r"\[([^\]]*)\]\([^)]*\)")


def slug(heading: str) -> str:
    """The anchor MkDocs' toc gives a heading: its text as rendered (code marks, emphasis and
    link targets gone), ASCII, lowercased, punctuation dropped, spaces and hyphens one hyphen."""
    text = INLINE_LINK.sub(r"\1", heading).replace("`", "").replace("**", "")
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(page: str) -> set[str]:
    """The anchors of a Markdown page's headings (not of `#` lines inside code blocks); a
    repeated heading gets `_1`, `_2`... as toc numbers it."""
    found: set[str] = set()
    fenced = False
    for line in page.splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
            continue
        match = None if fenced else HEADING.match(line)
        if match is None:
            continue
        explicit = EXPLICIT_ID.search(match[2])
        anchor = explicit[1] if explicit else slug(match[2])
        base, number = anchor, 0
        while anchor in found:
            number += 1
            anchor = f"{base}_{number}"
        found.add(anchor)
    return found


def broken_pointers(text: str, docs: Path = DOCS) -> list[str]:
    """The pointers in `text` to a page that does not exist or a heading it does not have."""
    broken = []
    for match in POINTER.finditer(text):
        page, anchor = docs / match[1], match[2]
        if not page.is_file():
            broken.append(f"{match[0]}: no such page")
        elif anchor is not None and anchor not in anchors(page.read_text(encoding="utf-8")):
            broken.append(f"{match[0]}: no heading with that anchor")
    return broken


def _scanned() -> list[Path]:
    here = Path(__file__).resolve()
    files = [ROOT / name for name in SCANNED_FILES if (ROOT / name).is_file()]
    for folder in SCANNED_FOLDERS:
        files += sorted(p for p in (ROOT / folder).rglob("*.py") if p.resolve() != here)
    # The documented production example's files say where they are explained.
    files += sorted(p for p in (ROOT / "examples").rglob("*") if p.is_file())
    return files


def test_every_docs_pointer_in_the_code_resolves() -> None:
    texts = {path: path.read_text(encoding="utf-8") for path in _scanned()}
    pointers = sum(len(POINTER.findall(text)) for text in texts.values())
    assert pointers >= 8, "the code's pointers into docs/ were not found"
    broken = [
        f"{path.relative_to(ROOT)}: {problem}"
        for path, text in texts.items()
        for problem in broken_pointers(text)
    ]
    assert not broken, "pointers into docs/ that lead nowhere:\n" + "\n".join(broken)


def test_no_design_citation_is_left() -> None:
    # The design the code cites is docs/architecture.md: a DESIGN file is not in the repository.
    cited = [
        f"{path.relative_to(ROOT)}:{number}"
        for path in _scanned()
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if DESIGN in line
    ]
    assert not cited, f"cite docs/architecture.md#<anchor> instead of {DESIGN}: {cited}"


def test_a_made_up_page_or_anchor_is_caught() -> None:
    assert broken_pointers("(docs/architecture.md#the-mqtt-contract)") == []
    assert broken_pointers("docs/architecture.md#the-mqtt-contracts") == [
        "docs/architecture.md#the-mqtt-contracts: no heading with that anchor"
    ]
    assert broken_pointers("see docs/architecture.md#design-7.") == [
        "docs/architecture.md#design-7: no heading with that anchor"
    ]
    assert broken_pointers("docs/nowhere.md#the-layers") == [
        "docs/nowhere.md#the-layers: no such page"
    ]


def test_anchors_are_those_mkdocs_makes() -> None:
    page = "\n".join(
        [
            "# Architecture",
            "## The agent's states",
            "## agent.yaml",
            "## The reconciler's status: `<prefix>/reconciler/status` (retained)",
            "## Push, not poll: `--webhook`",
            "```sh",
            "# not a heading",
            "```",
            "## Twice",
            "## Twice",
            "## Named { #given-id }",
        ]
    )
    assert anchors(page) == {
        "architecture",
        "the-agents-states",
        "agentyaml",
        "the-reconcilers-status-prefixreconcilerstatus-retained",
        "push-not-poll-webhook",
        "twice",
        "twice_1",
        "given-id",
    }
