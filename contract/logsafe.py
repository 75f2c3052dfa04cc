"""Log lines that text from robots and peers cannot forge: one formatter for every handler.

Agent-safe: the standard library only.
"""

from __future__ import annotations

import logging
import traceback

from robotconf.contract.textsafe import printable

_CAUSE = "The above exception was the direct cause of the following exception:"
_CONTEXT = "During handling of the above exception, another exception occurred:"


class SafeFormatter(logging.Formatter):
    """A record is one line: its message, and every field the format shows, with control
    characters, line breaks and bidi controls escaped (`textsafe.printable`), so that a
    robot's status message can neither start a line of its own nor drive a terminal. A
    traceback keeps its own lines (its frames come from the code), but the exception's
    message, which may quote a peer's text, is escaped as the record's is."""

    def format(self, record: logging.LogRecord) -> str:
        record.message = record.getMessage()
        if self.usesTime():
            record.asctime = self.formatTime(record, self.datefmt)
        text = printable(self.formatMessage(record))
        exc = record.exc_info[1] if record.exc_info else None
        if exc is not None:
            # Cached on the record, so that another handler's plain formatter shows it too.
            record.exc_text = format_exception(exc)
            text += "\n" + record.exc_text
        elif record.exc_text:  # formatted elsewhere (a record from another process)
            text += "\n" + _each_line(record.exc_text)
        if record.stack_info:
            text += "\n" + _each_line(self.formatStack(record.stack_info))
        return text


def format_exception(exc: BaseException) -> str:
    """`exc` as Python prints it (its chain, each with its traceback), except that what an
    exception says (its message, its notes) is escaped to one line each: only the traceback's
    own structure makes lines."""
    return "\n".join(_exception_lines(exc, set()))


def _exception_lines(exc: BaseException, seen: set[int]) -> list[str]:
    seen.add(id(exc))
    lines: list[str] = []
    cause, context = exc.__cause__, exc.__context__
    if cause is not None and id(cause) not in seen:
        lines += [*_exception_lines(cause, seen), "", _CAUSE, ""]
    elif context is not None and not exc.__suppress_context__ and id(context) not in seen:
        lines += [*_exception_lines(context, seen), "", _CONTEXT, ""]
    if exc.__traceback__ is not None:
        lines.append("Traceback (most recent call last):")
        frames = "".join(traceback.format_tb(exc.__traceback__))
        lines += _each_line(frames.rstrip("\n")).split("\n")
    lines.append(_final_line(exc))
    notes = getattr(exc, "__notes__", None)
    if isinstance(notes, list):
        lines += [printable(str(note)) for note in notes]
    # An exception group (Python 3.11+): each of its exceptions, after a line naming it.
    inner = getattr(exc, "exceptions", None)
    if isinstance(inner, tuple) and all(isinstance(e, BaseException) for e in inner):
        for number, member in enumerate(inner, 1):
            if id(member) not in seen:
                lines += ["", f"[exception {number} of {len(inner)} in the group]"]
                lines += _exception_lines(member, seen)
    return lines


def _final_line(exc: BaseException) -> str:
    kind = type(exc)
    name = kind.__qualname__
    if kind.__module__ not in ("builtins", "__main__"):
        name = f"{kind.__module__}.{name}"
    try:
        said = str(exc)
    except Exception:  # a broken __str__ must not lose the log line
        said = "<exception str() failed>"
    return printable(f"{name}: {said}" if said else name)


def _each_line(text: str) -> str:
    """Text whose line breaks are its own: each line made printable on its own."""
    return "\n".join(printable(line) for line in text.split("\n"))


def escape_stray_records() -> None:
    """A command that sets up no logging of its own still prints an error a library logs
    (a bug in a network callback), through Python's last-resort handler: escaped too. Not
    warnings: what goes wrong with the broker, the command says itself, once."""
    handler = logging.StreamHandler()
    handler.setLevel(logging.ERROR)
    handler.setFormatter(SafeFormatter("robotconf: %(message)s"))
    logging.lastResort = handler
