"""A ROS 2 peer for the ROS-leaf tests (test code, not product code): an action server, a service, a publisher and
a subscriber, each logging what it saw on stdout, one line per event, flushed.

* ``/gripper/gripper_cmd`` (control_msgs/action/GripperCommand): a goal runs ``max_effort / 100`` seconds (a
  test's way to ask for a short or a long goal) with feedback, then succeeds with ``position`` = the goal's and
  ``reached_goal`` = position >= 0 (a negative position aborts);
  a cancel request is accepted and the goal ends CANCELED (logged ``canceled``)
* ``/camera/change_state`` (lifecycle_msgs/srv/ChangeState): ``success`` = transition id is 3 (activate)
* ``/door_open`` (std_msgs/msg/Bool): published every 50 ms, ``data`` = ``--door-open``
* ``/beacon`` (std_msgs/msg/String): every message received is logged ``beacon <data>``

Prints ``ready`` once everything is up; stops on SIGTERM.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time


def log(*words: object) -> None:
    print(*words, flush=True)


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--door-open", default="true")
    args = parser.parse_args()

    from bt_meta.ros2.environment import import_rclpy
    from bt_meta.ros2.interfaces import load_control_msgs

    rclpy = import_rclpy()
    load_control_msgs()
    from control_msgs.action import GripperCommand
    from lifecycle_msgs.srv import ChangeState
    from rclpy.action import ActionServer, CancelResponse, GoalResponse
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
    from std_msgs.msg import Bool, String

    rclpy.init()
    node = rclpy.create_node("leaf_peer")
    group = ReentrantCallbackGroup()

    def execute(goal_handle):
        position = goal_handle.request.command.position
        log("goal", position, goal_handle.request.command.max_effort)
        deadline = time.monotonic() + goal_handle.request.command.max_effort / 100.0
        while time.monotonic() < deadline:
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                log("canceled")
                return GripperCommand.Result(position=position)
            feedback = GripperCommand.Feedback(position=position)
            goal_handle.publish_feedback(feedback)
            time.sleep(0.02)
        result = GripperCommand.Result(position=position, reached_goal=position >= 0.0, effort=1.5)
        if position < 0.0:
            goal_handle.abort()
            log("aborted")
            return result
        goal_handle.succeed()
        log("succeeded")
        return result

    ActionServer(node, GripperCommand, "/gripper/gripper_cmd", execute, callback_group=group,
                 goal_callback=lambda _goal: GoalResponse.ACCEPT,
                 cancel_callback=lambda _goal: CancelResponse.ACCEPT)

    def change_state(request, response):
        log("change_state", request.transition.id)
        response.success = request.transition.id == 3
        return response

    node.create_service(ChangeState, "/camera/change_state", change_state, callback_group=group)
    door = node.create_publisher(Bool, "/door_open", 1)
    open_now = args.door_open == "true"
    node.create_timer(0.05, lambda: door.publish(Bool(data=open_now)), callback_group=group)
    node.create_subscription(String, "/beacon", lambda message: log("beacon", message.data), 10,
                             callback_group=group)

    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    log("ready")
    with contextlib.suppress(ExternalShutdownException, KeyboardInterrupt):
        executor.spin()
    return 0


if __name__ == "__main__":
    sys.exit(main())
