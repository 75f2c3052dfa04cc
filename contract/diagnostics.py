"""Diagnostics: one located finding (`path:line:col: severity CODE message`) and their formats."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass

from robotconf.contract.codes import Severity as Severity
from robotconf.contract.codes import require
from robotconf.contract.textsafe import printable


@dataclass(frozen=True, order=True)
class Diagnostic:
    """One finding. Fields are ordered so that sorting a list sorts by file, line, column."""

    path: str
    line: int
    col: int
    severity: Severity
    code: str
    message: str

    def __post_init__(self) -> None:
        require(self.code, self.severity)

    def __str__(self) -> str:
        # Names and values come from the files: escaped, so that none can forge a line.
        return (
            f"{printable(self.path)}:{self.line}:{self.col}: {self.severity.value} {self.code} "
            f"{printable(self.message)}"
        )

    @property
    def is_error(self) -> bool:
        return self.severity is Severity.ERROR


def closest(name: str, known: Iterable[str]) -> str | None:
    """The known name a near miss was meant to be (what did-you-mean suggests), if any."""
    import difflib  # only a near miss pays for it: validate's start-up matters (pre-commit)

    candidates = sorted(set(known))
    close = difflib.get_close_matches(name, candidates, n=1, cutoff=0.6)
    if close:
        return close[0]
    return {c.lower(): c for c in candidates}.get(name.lower())


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """` (did you mean 'x'?)` for a near miss, else a short list of what exists."""
    candidates = sorted(set(known))
    meant = closest(name, candidates)
    if meant is not None:
        return f"; did you mean '{meant}'?"
    if not candidates:
        return "; none exist"
    shown = ", ".join(candidates[:8])
    more = f", ... ({len(candidates)} in all)" if len(candidates) > 8 else ""
    return f"; known: {shown}{more}"


_KIND_OF = {str: "text", int: "a whole number", float: "a number"}


def describe_value(value: object, *, kind: bool = True) -> str:
    """A value as an error quotes it: `'fast' (text)`, `3 (a whole number)`, `a list`; with
    `kind=False` (a value of the right type out of range) the scalar alone."""
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list | tuple):
        return "a list"
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return str(value).lower()
    text = repr(value)
    text = text if len(text) <= 40 else text[:37] + "..."
    return f"{text} ({_KIND_OF.get(type(value), type(value).__name__)})" if kind else text


def format_text(diagnostics: list[Diagnostic]) -> str:
    return "".join(f"{d}\n" for d in diagnostics)


def _tally(diagnostics: list[Diagnostic]) -> tuple[int, int]:
    """How many errors and how many warnings."""
    errors = sum(d.is_error for d in diagnostics)
    return errors, len(diagnostics) - errors


def format_json(diagnostics: list[Diagnostic]) -> str:
    import json  # text output, the pre-commit default, does without it

    rows = [dict(asdict(d), severity=d.severity.value) for d in diagnostics]
    errors, warnings = _tally(diagnostics)
    summary = {"errors": errors, "warnings": warnings, "diagnostics": rows}
    return json.dumps(summary, indent=2) + "\n"


def _github_escape(value: str, *, prop: bool = False) -> str:
    value = printable(value).replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")
    if prop:
        value = value.replace(":", "%3A").replace(",", "%2C")
    return value


def format_github(diagnostics: list[Diagnostic]) -> str:
    """GitHub Actions workflow commands: each finding becomes an annotation on the PR diff."""
    lines = []
    for d in diagnostics:
        props = ",".join(
            [
                f"file={_github_escape(d.path, prop=True)}",
                f"line={d.line}",
                f"col={d.col}",
                f"title={_github_escape(d.code, prop=True)}",
            ]
        )
        lines.append(f"::{d.severity.value} {props}::{_github_escape(d.message)}\n")
    return "".join(lines)


def summary_line(diagnostics: list[Diagnostic], files: int) -> str:
    errors, warnings = _tally(diagnostics)
    if not diagnostics:
        return f"{files} files checked: no problems"
    return f"{files} files checked: {errors} error(s), {warnings} warning(s)"
