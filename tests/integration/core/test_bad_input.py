"""Bad input is a clean, located error, never a traceback (the corpus in corpus/bad-input/).

Each case drops one file into a copy of the example lab and runs the real `robotconf validate`
in a subprocess: exit 1, no traceback, and `<path>:<line>:<col>: error <CODE> ...` for it.
"""

from __future__ import annotations

import re
import resource
import shutil
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

from robotconf.contract.yamlio import MAX_FILE_BYTES
from tests.support.lab import ROBOTCONF, ROOT

CORPUS = ROOT / "tests" / "corpus" / "bad-input"
MEMORY_LIMIT = 512 * 1024 * 1024


def _oversized() -> bytes:
    head = b"capability: turtlebot3-camera\n"
    filler = b"# " + b"padding " * 12 + b"\n"
    count = (MAX_FILE_BYTES - len(head)) // len(filler) + 1
    data = head + filler * count
    assert len(data) > MAX_FILE_BYTES
    return data


def _deep_nesting_huge() -> bytes:
    depth = 100_000
    return b"capability: turtlebot3-camera\nknowledge:\n  k: " + b"[" * depth + b"]" * depth + b"\n"


def _block_nesting_huge() -> bytes:
    """50,000 nested block sequences in 100 kB: libyaml's composer overflowed the C stack."""
    return b"capability: turtlebot3-camera\nknowledge:\n  k:\n    " + b"- " * 50_000 + b"1\n"


def _hidden_nesting() -> bytes:
    """60,000 levels whose brackets balance out, the closing ones in comments: a bracket
    count that trusted closing brackets let it through to the composer, which crashed."""
    step = b"[" * 20 + b" #" + b"]" * 20 + b"\n"
    return b"capability: turtlebot3-camera\nknowledge:\n  k: " + step * 3_000


def _too_many_nodes() -> bytes:
    """A quarter of a million values in 1 MB: composed, some 30 s and 1.4 GB per 8 MiB."""
    return b"capability: turtlebot3-camera\nknowledge:\n  k: [" + b"a," * 250_000 + b"]\n"


GENERATORS: dict[str, Callable[[], bytes]] = {
    "oversized": _oversized,
    "deep-nesting-huge": _deep_nesting_huge,
    "block-nesting-huge": _block_nesting_huge,
    "hidden-nesting": _hidden_nesting,
    "too-many-nodes": _too_many_nodes,
}


@dataclass(frozen=True)
class Case:
    name: str
    place: str
    code: str | None
    at: str | None
    message: str | None
    source: str  # a corpus file name, or a GENERATORS key
    bug: str | None  # what the tool gets wrong today (the case is a strict xfail)

    def content(self) -> bytes:
        if self.source in GENERATORS:
            return GENERATORS[self.source]()
        return (CORPUS / self.source).read_bytes()


def _load_cases() -> list[Case]:
    rows = yaml.safe_load((CORPUS / "cases.yaml").read_text(encoding="utf-8"))
    cases = []
    for row in rows:
        source = row.get("generate") or row["file"]
        name = Path(source).stem if "file" in row else source
        cases.append(
            Case(
                name,
                row["place"],
                row["code"],
                row.get("at"),
                row.get("message"),
                source,
                row.get("bug"),
            )
        )
    return cases


CASES = _load_cases()


def _param(case: Case) -> Any:
    marks = [pytest.mark.xfail(strict=True, reason=f"known bug: {case.bug}")] if case.bug else []
    return pytest.param(case, id=case.name, marks=marks)


def _lab(tmp_path: Path) -> Path:
    root = tmp_path / "lab"
    for part in ("models", "configs"):
        shutil.copytree(ROOT / part, root / part)
    return root


def _place(root: Path, case: Case) -> None:
    target = root / case.place
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(case.content())


def _validate(
    root: Path, *args: str, preexec_fn: Callable[[], None] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [ROBOTCONF, "validate", "--repo", str(root), *args],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=preexec_fn,
    )


def _assert_clean_failure(done: subprocess.CompletedProcess[str], case: Case) -> str:
    """The located line for the case's file, after checking exit 1 and no traceback."""
    output = done.stdout + done.stderr
    assert "Traceback" not in output, output
    assert done.returncode == 1, f"exit {done.returncode}\n{output}"
    pattern = re.compile(
        rf"^{re.escape(case.place)}:{re.escape(case.at or '')}: error {case.code} .+$",
        re.MULTILINE,
    )
    found = pattern.search(done.stdout)
    own = [line for line in done.stdout.splitlines() if line.startswith(f"{case.place}:")]
    assert found, f"no '{case.place}:{case.at}: error {case.code}' line; the file got:\n" + (
        "\n".join(own) or output
    )
    return found.group(0)


def test_corpus_table_and_files_agree() -> None:
    listed = {c.source for c in CASES if c.source not in GENERATORS}
    on_disk = {p.name for p in CORPUS.iterdir() if p.name != "cases.yaml"}
    assert listed == on_disk


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_bad_input_is_a_located_error(tmp_path: Path, case: Case) -> None:
    root = _lab(tmp_path)
    _place(root, case)
    done = _validate(root)
    if case.code is None:  # input that looks odd but is valid
        output = done.stdout + done.stderr
        assert done.returncode == 0, output
        assert "Traceback" not in output
        assert done.stdout == ""
        return
    line = _assert_clean_failure(done, case)
    if case.message:
        assert case.message in line, line


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def test_alias_bomb_is_refused_in_bounded_memory(tmp_path: Path) -> None:
    root = _lab(tmp_path)
    bomb = "models/environments/billion-laughs.yaml"
    (root / bomb).write_bytes((CORPUS / "billion-laughs.yaml").read_bytes())
    done = _validate(root, preexec_fn=_limit_memory)
    output = done.stdout + done.stderr
    assert "Traceback" not in output and "MemoryError" not in output, output
    assert done.returncode == 1, output
    assert re.search(rf"^{re.escape(bomb)}:\d+:\d+: error RC005 ", done.stdout, re.MULTILINE)


def test_every_diagnostic_line_of_the_corpus_is_well_formed(tmp_path: Path) -> None:
    """All committed corpus files at once: every output line is `path:line:col: severity CODE`."""
    root = _lab(tmp_path)
    committed = [c for c in CASES if c.bug is None and c.source not in GENERATORS]
    for case in committed:
        _place(root, case)
    done = _validate(root)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    shape = re.compile(r"^[^:\s]+:\d+:\d+: (error|warning) RC\d{3} \S.*$")
    bad = [line for line in done.stdout.splitlines() if not shape.match(line)]
    assert not bad, bad
    reported = {line.split(":", 1)[0] for line in done.stdout.splitlines()}
    expected = {c.place for c in committed if c.code is not None}
    assert expected <= reported, sorted(expected - reported)
