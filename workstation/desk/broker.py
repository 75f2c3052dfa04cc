"""Whether the broker is there: the one place every desk operation (status, logs, restart,
rollout, promote, draft, and the browser view's operators) waits for it and says, in one line,
why it is not there and what to do."""

from __future__ import annotations

from typing import TYPE_CHECKING

from robotconf.contract.errors import CliError
from robotconf.contract.mqtt import NOTHING_LISTENS

if TYPE_CHECKING:
    from robotconf.readmodel.retained import RetainedView

# What to do when nothing listens at the broker's address, and when something there turned
# the connection away: said by every desk command alike.
START_ONE = (
    "is the broker running? (`./dev up` or `robotconf up` starts one; --broker URL names another)"
)
CHECK_LISTENER = (
    "is that a broker's listener, and does it speak what --broker's scheme says "
    "(mqtt:// plain, mqtts:// TLS)?"
)


def refused(url: str, reason: str) -> CliError:
    """The broker turned this client away: waiting longer would not change that."""
    return CliError(
        f"the broker at {url} refused the connection ({reason}): check --username and "
        "--password-file (for robotconf up's broker, give no broker options: run the command "
        "in up's repository, or with --repo)"
    )


def wait_for_broker(view: RetainedView, wait: float) -> None:
    """Returns once `view` holds the broker's retained messages. Raises a one-line CliError at
    once when the broker refuses the login or cannot be connected to (refused, reset, closed),
    and after `wait` seconds only when the network stays silent: the one place every desk
    command (status, logs, restart, rollout, promote, draft) says the broker is not there."""
    if view.wait_synced(wait, or_refused=True):
        return
    raise broker_missing(view, wait)


def broker_missing(view: RetainedView, wait: float) -> CliError:
    """Why `view` has nothing after `wait_for_broker` gave up, and what to do about it."""
    url = view.connection.address.url
    if view.refused is not None:
        return refused(url, view.refused)
    if view.closed is not None:
        hint = START_ONE if view.closed == NOTHING_LISTENS else CHECK_LISTENER
        return CliError(f"cannot connect to the broker at {url} ({view.closed}): {hint}")
    return CliError(
        f"no answer from the broker at {url} within {wait:g} s ({view.silence()}): is it "
        "running and reachable from here? (--broker URL, --wait S)"
    )
