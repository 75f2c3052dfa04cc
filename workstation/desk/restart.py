"""A robot's brain started again from the desk, without a commit: the request sent to its
agent (signed when a key is given) and the status that confirms it; the one way `robotconf
restart` and the browser view's operators restart a robot."""

from __future__ import annotations

import queue
import time
from typing import TYPE_CHECKING

from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.launch import RestartRequest
from robotconf.contract.mqtt import Connection
from robotconf.contract.wire import AgentState, AgentStatus
from robotconf.workstation.desk.robot import RobotDesk, online_robot

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey


def _confirmed(desk: RobotDesk, issued_at: float, wait: float) -> AgentStatus | None:
    """The robot's first status that records this restart, within `wait` seconds."""
    deadline = time.monotonic() + wait
    while (left := deadline - time.monotonic()) > 0:
        try:
            status = desk.statuses.get(timeout=min(left, 0.5))
        except queue.Empty:
            continue
        if status.restart_requested_at == issued_at:
            return status
    return None


def _send_restart(
    desk: RobotDesk, robot_id: str, by: str, key: Ed25519PrivateKey | None, timeout: float
) -> float:
    """Publish the restart request, signed with `key` if any; when it was issued."""
    # Microseconds, as `sign` stamps them: the status that confirms it names the same time.
    issued_at = round(time.time(), 6)
    request = RestartRequest(robot_id=robot_id, requested_by=by, issued_at=issued_at)
    if key is not None:
        from robotconf.contract.signing import sign

        request = sign(request, key, issued_at)
    if not desk.send(desk.topics.restart(robot_id), request.payload(), timeout):
        raise CliError(
            f"the broker did not take the restart request "
            f"({desk.view.last_error or 'no acknowledgement'})"
        )
    return request.issued_at


def request_restart(
    connection: Connection,
    prefix: str,
    robot_id: str,
    by: str,
    key: Ed25519PrivateKey | None,
    wait: float,
) -> AgentStatus:
    """Asks `robot_id`'s agent to restart its brain (signed with `key` when given) and waits
    up to `wait` seconds for the status that confirms it: the one way `robotconf restart` and
    the UI's operators restart a robot. Blocks; raises CliError saying why it did not happen
    (robot unknown, offline or idle, broker silent, no confirmation)."""
    with RobotDesk(connection, prefix, robot_id, logs=False) as desk:
        robot = online_robot(desk, min(wait, 10.0), "a restart would be lost")
        status = robot.status
        if status is None or status.state is AgentState.IDLE:
            raise CliError(
                f"nothing to restart: {robot_id} has no launch request (it is idle)",
                ExitCode.FINDINGS,
            )
        issued_at = _send_restart(desk, robot_id, by, key, min(wait, 10.0))
        confirmed = _confirmed(desk, issued_at, wait)
    if confirmed is None:
        raise CliError(
            f"{robot_id} did not confirm the restart within {wait:g} s: its agent refused it "
            "(unsigned or wrongly signed where it verifies, clocks more than 5 minutes apart) "
            f"or never got it (the ACL lets only operators and the reconciler ask); "
            f"robotconf logs {robot_id} shows why",
            ExitCode.FINDINGS,
        )
    return confirmed
