"""Why a ROS 2 run could not start or could not go on: typed, so the CLI reports one line and the right status.

Offers:

* :class:`Ros2Unavailable` -- the ``[ros2]`` extra (rclpy, the message packages, the generators) is not installed
* :class:`InterfaceGenerationError` -- control_msgs could not be generated (cmake or a compiler missing or failing)
* :class:`ServerUnavailable` -- an action server did not appear within its timeout (exit 2, before any motion)
* :class:`ConnectionLost` -- a goal's result or the robot state stopped arriving in the middle of a run
"""

from __future__ import annotations

from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["ConnectionLost", "InterfaceGenerationError", "Ros2Unavailable", "ServerUnavailable"]


class Ros2Unavailable(BtMetaError):
    """rclpy or a message package cannot be imported."""


class InterfaceGenerationError(BtMetaError):
    """Generating the kept interface definitions failed."""


class ServerUnavailable(UserInputError):
    """An action server or topic the config names is not there: the config or the robot's bringup is wrong."""


class ConnectionLost(BtMetaError):
    """The robot stopped answering mid-run (a goal's result or a fresh state did not arrive in time)."""
