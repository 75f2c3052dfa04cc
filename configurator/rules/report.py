"""Collects diagnostics located at a key or value of an entry's file."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from configurator.diagnostics import Diagnostic, Severity
from configurator.repository import Entry


class Reporter:
    def __init__(self) -> None:
        self.found: list[Diagnostic] = []

    def error(
        self,
        entry: Entry[Any],
        loc: Sequence[str | int],
        code: str,
        message: str,
        *,
        key: bool = False,
    ) -> None:
        self._add(entry, loc, Severity.ERROR, code, message, key)

    def warning(
        self,
        entry: Entry[Any],
        loc: Sequence[str | int],
        code: str,
        message: str,
        *,
        key: bool = False,
    ) -> None:
        self._add(entry, loc, Severity.WARNING, code, message, key)

    def _add(
        self,
        entry: Entry[Any],
        loc: Sequence[str | int],
        severity: Severity,
        code: str,
        message: str,
        key: bool,
    ) -> None:
        line, col = entry.doc.locate(loc, key=key)
        self.found.append(Diagnostic(entry.path, line, col, severity, code, message))
