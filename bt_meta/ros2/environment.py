"""The process environment a ROS 2 node of bt-meta starts in, and the one place rclpy is imported.

Discovery stays on this machine unless the user says otherwise: ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` is set
when the environment does not set it (DDS multicast would otherwise leave the machine). The wheels carry Fast DDS
only, so ``RMW_IMPLEMENTATION`` defaults to it. Both must be in place before ``rclpy.init``.

Offers:

* :func:`prepare_environment` -- the defaults above (an explicit value in the environment wins)
* :func:`import_rclpy` -- rclpy, or :class:`~bt_meta.ros2.errors.Ros2Unavailable` naming the extra
"""

from __future__ import annotations

import os
from typing import Any

from bt_meta.ros2.errors import Ros2Unavailable

__all__ = ["DEFAULTS", "import_rclpy", "prepare_environment"]

DEFAULTS = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp"}


def prepare_environment() -> dict[str, str]:
    """Set the defaults the environment lacks; returns the values in force."""
    for key, value in DEFAULTS.items():
        os.environ.setdefault(key, value)
    return {key: os.environ[key] for key in DEFAULTS}


def import_rclpy() -> Any:
    prepare_environment()
    try:
        import rclpy
    except ImportError as error:
        raise Ros2Unavailable(f"ROS 2 support needs the extra: pip install 'bt-meta[ros2]' ({error})") from None
    return rclpy
