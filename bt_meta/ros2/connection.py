"""The ROS 2 world's connection to a robot: its own rclpy context and node, an executor on a background thread,
the robot state and camera subscriptions and one action client per arm controller and gripper of the config.

:meth:`Connection.open` waits for every action server and for a first state, up to the config's server timeout:
a missing one is a :class:`~bt_meta.ros2.errors.ServerUnavailable` naming the action (or topic) and the timeout,
with the action servers that are visible, before any goal is sent. rclpy installs no signal handlers here, so
Ctrl-C stays Python's KeyboardInterrupt (the CLI's exit 130) and SIGTERM the CLI's own.

Offers:

* :class:`Connection` -- ``open()``, ``trajectory[arm]``, ``gripper[arm]``, ``state``, ``camera``, ``cancel_all()``,
  ``close()``
"""

from __future__ import annotations

import atexit
import contextlib
import threading
import time
from typing import Any

from bt_meta.ros2.errors import ServerUnavailable

__all__ = ["Connection"]


class Connection:
    def __init__(self, config: Any, node_name: str = "bt_meta_world") -> None:
        from bt_meta.ros2.environment import import_rclpy
        from bt_meta.ros2.interfaces import load_control_msgs

        rclpy = import_rclpy()
        load_control_msgs()
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from bt_meta.ros2.action_clients import GripperClient, TrajectoryClient
        from bt_meta.ros2.camera_subscriber import CameraFrames
        from bt_meta.ros2.robot_state import RobotState

        self.config = config
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(node_name, context=self.context)
        # one thread takes every response and runs every request (see ActionClient), the world waits on events
        self.executor = SingleThreadedExecutor(context=self.context)
        self.state = RobotState(self.node, config)
        self.camera = CameraFrames(self.node, config)
        self.trajectory = {arm: TrajectoryClient(self.node, config.trajectory_action(arm), spec.joints, self.executor)
                           for arm, spec in config.arms.items()}
        self.gripper = {arm: GripperClient(self.node, spec.gripper_action, self.executor)
                        for arm, spec in config.arms.items() if spec.gripper_action is not None}
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="bt-meta-ros2", daemon=True)
        self._thread.start()
        self._closed = False
        # a command that never closes its world (tick) must not leave rclpy's threads to the interpreter's exit:
        # the process aborts there ("terminate called without an active exception")
        atexit.register(self.close)

    def _spin(self) -> None:
        spin_until_shutdown(self.executor, self.context)

    def open(self) -> None:
        """Every action server and a first state within the server timeout, else ServerUnavailable."""
        timeout = self.config.server_timeout
        where = self.config.path or "--ros2"
        deadline = time.monotonic() + timeout
        clients = [*self.trajectory.values(), *self.gripper.values()]
        for client in clients:
            if not client.wait_for_server(max(0.0, deadline - time.monotonic())):
                raise ServerUnavailable(f"no action server {client.action} within the {timeout:g} s server timeout "
                                        f"(action servers seen: {self._seen_actions()}); nothing was moved", where)
        if not self.state.wait_until(0, max(0.0, deadline - time.monotonic())):
            raise ServerUnavailable(f"no {self.config.joint_states} and {self.config.object_poses} messages within "
                                    f"the {timeout:g} s server timeout; nothing was moved", where)

    def _seen_actions(self) -> str:
        from rclpy.action import get_action_names_and_types

        names = sorted(name for name, _types in get_action_names_and_types(self.node))
        return ", ".join(names) or "none"

    def record(self, tap: Any) -> None:
        """``tap(topic, message)`` sees the states and images received and the trajectories sent from now on."""
        self.state.tap = tap
        self.camera.tap = tap
        for client in self.trajectory.values():
            client.tap = tap

    def cancel_all(self) -> int:
        return sum(client.cancel_active() for client in [*self.trajectory.values(), *self.gripper.values()])

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        try:
            self.cancel_all()
        finally:
            self.context.try_shutdown()
            self._thread.join(timeout=2.0)
            with contextlib.suppress(Exception):  # handles already gone with the context
                self.executor.shutdown(timeout_sec=1.0)
                self.node.destroy_node()


def spin_until_shutdown(executor: Any, context: Any) -> None:
    """Spin ``executor`` on its own thread until ``context`` shuts down (a shutdown under the spin is the close)."""
    from rclpy.executors import ExternalShutdownException

    try:
        while context.ok():
            executor.spin_once(timeout_sec=0.05)
    except (ExternalShutdownException, RuntimeError):
        pass
