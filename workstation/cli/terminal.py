"""rich on the workstation: screens for a terminal, plain text for pipes, files and CI.

Plain means no colour, no control codes and no line wrapped or cut. Anything from files or the
broker reaches rich as `rich.text.Text` (see `safe`), never as markup.
"""

from __future__ import annotations

import io
import sys
from typing import TextIO

from rich.console import Console, RenderableType
from rich.text import Text

from robotconf.contract.textsafe import printable

PLAIN_WIDTH = 100_000  # wide enough that no table or tree line is ever wrapped or cut


def safe(text: str, style: str = "") -> Text:
    """Text from a file or a peer for rich: control characters escaped, "[bold]" kept literal."""
    return Text(printable(text), style=style)


def is_terminal(out: TextIO | None = None) -> bool:
    stream = sys.stdout if out is None else out
    try:
        return stream.isatty()
    except ValueError:  # a closed stream
        return False


def terminal_console(out: TextIO | None = None) -> Console:
    """A console for a terminal: colours, its width, live screens."""
    return Console(file=out or sys.stdout, highlight=False, emoji=False, markup=False)


def plain_text(renderable: RenderableType) -> str:
    """`renderable` as plain text: no colour or control code, no wrapping, no trailing blanks."""
    buffer = io.StringIO()
    console = Console(
        file=buffer,
        width=PLAIN_WIDTH,
        color_system=None,
        force_terminal=False,
        force_jupyter=False,
        highlight=False,
        emoji=False,
        markup=False,
        legacy_windows=False,
    )
    console.print(renderable, crop=False, soft_wrap=False)
    return "".join(line.rstrip() + "\n" for line in buffer.getvalue().splitlines())


def show(renderable: RenderableType, out: TextIO | None = None) -> None:
    """Prints `renderable`: drawn for a terminal, plain otherwise."""
    stream = sys.stdout if out is None else out
    if is_terminal(stream):
        terminal_console(stream).print(renderable)
    else:
        stream.write(plain_text(renderable))
    stream.flush()
