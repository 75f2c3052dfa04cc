"""Dying with a parent: Linux's parent-death signal (prctl PR_SET_PDEATHSIG), asked for by `up`.

Used only when `robotconf up` runs the agent (see `ENV`); a robot's agent outlives nobody.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
from collections.abc import Callable
from types import FrameType

# Set by `robotconf up` to its own pid: the agent then dies with `up`, its brain with the agent.
ENV = "ROBOTCONF_DIE_WITH_PARENT"
PR_SET_PDEATHSIG = 1


def _prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None
    function: Callable[..., int] = libc.prctl
    return function


def take_request() -> int | None:
    """The parent pid `up` gave, removed from the environment so that the brain does not
    inherit the request (its own parent is the agent, not `up`)."""
    raw = os.environ.pop(ENV, None)
    os.environb.pop(ENV.encode(), None)  # a copy of its own: brains get their env from it
    try:
        return int(raw) if raw else None
    except ValueError:
        return None


def die_with_parent(parent: int) -> bool:
    """Call once the stop handlers are installed: SIGHUP then reaches this process when its
    parent dies, and stops it as SIGTERM would (it stops its brain and says so). False when
    the parent is already gone (nobody will send it); True off Linux (nothing is asked).

    SIGHUP, handled once, rather than SIGTERM: the kernel sends the signal each time the
    process is re-parented, i.e. once per thread of a killed multi-threaded parent, and a
    second SIGTERM means "do not wait" to the agent (its brain would be killed, not stopped)."""
    stop = signal.getsignal(signal.SIGTERM)
    # One token, taken by list.pop (one C call): a Python handler can run again between two
    # bytecodes of itself, and the kernel's SIGHUPs come in a burst, so a flag tested and then
    # set let two through (a loaded run logged "SIGHUP received: stopping" twice, and the
    # second, as a second SIGTERM does, killed the brain instead of stopping it).
    token = [True]

    def once(signum: int, frame: FrameType | None) -> None:
        try:
            token.pop()
        except IndexError:
            return
        if callable(stop):
            stop(signum, frame)

    signal.signal(signal.SIGHUP, once)
    prctl = _prctl()
    if prctl is not None:
        prctl(PR_SET_PDEATHSIG, int(signal.SIGHUP), 0, 0, 0)
    # The parent may have died between our fork and the prctl: then we were re-parented.
    return os.getppid() == parent


def child_setup(sig: signal.Signals = signal.SIGTERM) -> Callable[[], None] | None:
    """A preexec_fn giving a child `sig` when this process dies, or None off Linux.

    libc's prctl is resolved here, before the fork: the child only calls it (a preexec_fn runs
    in a forked copy of a threaded process, where loading a library could deadlock)."""
    prctl = _prctl()
    if prctl is None:
        return None
    parent = os.getpid()
    number = int(sig)

    def setup() -> None:
        prctl(PR_SET_PDEATHSIG, number, 0, 0, 0)
        if os.getppid() != parent:  # this process died before the prctl took effect
            os._exit(1)

    return setup
