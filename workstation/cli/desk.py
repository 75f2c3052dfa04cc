"""What `robotconf logs` and `robotconf restart` share: the robot found online on the broker,
or one line saying why it cannot be asked."""

from __future__ import annotations

from contract.errors import CliError, ExitCode
from reconciler.observed import RobotSeen
from workstation.cli.broker_options import wait_for_broker
from workstation.desk import RobotDesk


def online_robot(desk: RobotDesk, wait: float, why_online: str) -> RobotSeen:
    """The robot as the broker knows it, once its retained topics are read; raises CliError
    when the broker does not answer, knows nothing of the robot, or has it offline."""
    url = desk.connection.address.url
    wait_for_broker(desk.view, wait)
    robot = desk.robot()
    if robot is None:
        raise CliError(desk.unknown(wait).message(url), ExitCode.FINDINGS)
    if not robot.online:
        raise CliError(
            f"{desk.robot_id} is offline: {why_online} (robotconf status {desk.robot_id})",
            ExitCode.FINDINGS,
        )
    return robot
