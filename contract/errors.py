"""Exit codes and the one error every command raises; click-free, so the agent can use them."""

from __future__ import annotations

import enum


class ExitCode(enum.IntEnum):
    OK = 0
    FINDINGS = 1  # the repository or the fleet has problems the user asked about
    TOOL = 2  # the tool could not do its job: bad arguments, unreachable broker, bad revision
    INTERRUPTED = 130  # Ctrl-C, as a shell reports it


class CliError(Exception):
    """A problem the user can fix: printed as `robotconf: <message>`, exits with `code`."""

    def __init__(self, message: str, code: ExitCode = ExitCode.TOOL) -> None:
        super().__init__(message)
        self.message = message
        self.code = code
