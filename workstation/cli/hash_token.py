"""`robotconf hash-token`: the line an operators file keeps for an operator (`robotconf ui
--operators-file`): a token read from stdin (never an argument, which ps shows) hashed, or with
--new NAME a new random token, shown once, and its line."""

from __future__ import annotations

import getpass
import secrets
import sys

import click

from robotconf.contract.errors import CliError, ExitCode
from robotconf.workstation.ui.auth import MAX_TOKEN_FILE, token_in
from robotconf.workstation.ui.operators import hash_token, name_problem

STDIN = "the token on stdin"


def _read_token() -> str:
    """The token typed at the terminal (not echoed), or the one line piped in."""
    if sys.stdin.isatty():
        try:
            typed = getpass.getpass("token (not shown): ")
        except (EOFError, KeyboardInterrupt):
            raise CliError("no token typed: nothing to hash") from None
        return token_in(typed.encode("ascii", "replace"), STDIN)
    data = sys.stdin.buffer.read(MAX_TOKEN_FILE + 1)
    if len(data) > MAX_TOKEN_FILE:
        raise CliError(f"{STDIN} is over {MAX_TOKEN_FILE:,} bytes: give the token alone")
    return token_in(data, STDIN)


@click.command("hash-token")
@click.option(
    "--new",
    "new_name",
    metavar="NAME",
    default=None,
    help="make a new random token for operator NAME: its line `NAME HASH` on stdout, the "
    "token itself on stderr, once",
)
@click.option(
    "--name",
    "name",
    metavar="NAME",
    default=None,
    help="print the whole line, `NAME HASH`, for the token read from stdin",
)
def hash_token_command(new_name: str | None, name: str | None) -> ExitCode:
    """Print the hash of an operator's token, for `robotconf ui --operators-file`.

    Reads the token from stdin (typed unechoed at a terminal, or piped: never an argument,
    which ps shows) and prints its hash; the operators file keeps it on a line `NAME HASH`
    (--name NAME prints that whole line: `robotconf hash-token --name bob >> operators`).
    With --new NAME it makes a new token instead and prints the whole line (append it to the
    file: `robotconf hash-token --new alice >> operators`) and, on stderr, the token to give
    alice; it is not kept anywhere else."""
    for option, given in (("--name", name), ("--new", new_name)):
        problem = name_problem(given) if given is not None else None
        if problem is not None:
            raise CliError(f"{option} {problem}")
    if new_name is None:
        line = hash_token(_read_token()).text()
        print(f"{name} {line}" if name is not None else line)
        return ExitCode.OK
    if name is not None:
        raise CliError("--name names a token read from stdin, --new a new one: give one")
    token = secrets.token_urlsafe(32)
    print(f"{new_name} {hash_token(token).text()}")
    click.echo(f"the token of {new_name} (shown once, give it to them): {token}", err=True)
    return ExitCode.OK
