"""Collects diagnostics located at a key or value of an entry's file."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from robotconf.configurator.repository import Entry
from robotconf.contract.codes import severity_of
from robotconf.contract.diagnostics import Diagnostic, did_you_mean


class Reporter:
    def __init__(self) -> None:
        self.found: list[Diagnostic] = []

    def add(
        self,
        entry: Entry[Any],
        loc: Sequence[str | int],
        code: str,
        message: str,
        *,
        key: bool = False,
    ) -> None:
        """A finding at `loc` (the key itself with `key`), as severe as contract/codes.py
        declares its code."""
        severity = severity_of(code)
        line, col = entry.doc.locate(loc, key=key)
        self.found.append(Diagnostic(entry.path, line, col, severity, code, message))

    def unknown(
        self,
        entry: Entry[Any],
        loc: Sequence[str | int],
        code: str,
        message: str,
        name: str,
        known: Iterable[str],
        *,
        unreadable: bool = False,
        key: bool = False,
    ) -> None:
        """A reference to `name`, which is not among `known`: `message` and a did-you-mean hint.
        Nothing when the file `name` refers to exists but is `unreadable`: that file is reported
        itself, once."""
        if not unreadable:
            self.add(entry, loc, code, f"{message}{did_you_mean(name, known)}", key=key)
