"""The served simulator's ``control_msgs/action/FollowJointTrajectory`` servers, one per arm controller, as
ros2_control's joint trajectory controller offers them at ``/<controller>/follow_joint_trajectory``.

A goal names exactly the controller's joints (else it is rejected, as the controller does); its points are
executed in order: each point's positions become the motors' targets and the physics runs for the point's share of
the time (``time_from_start`` differences, in whole physics steps). The simulation's clock advances only while a
goal runs (lock-step: the same goals give the same physics as in-process). Feedback (desired, actual, error) is
published after every point (not with ``--fault no-feedback``), the state topics too. An empty trajectory or
times that do not increase abort with ``INVALID_GOAL``; a cancel request stops between points.

Offers:

* :class:`TrajectoryServer` -- the action server of one arm
"""

from __future__ import annotations

import sys
from typing import Any

from bt_meta.ros2.messages import duration_seconds, to_duration

__all__ = ["TrajectoryServer"]


class TrajectoryServer:
    def __init__(self, node: Any, server: Any, arm: Any, action: str) -> None:
        from control_msgs.action import FollowJointTrajectory
        from rclpy.action import ActionServer, CancelResponse

        self.node = node
        self.server = server
        self.arm = arm
        self.action = action
        self.goals = 0
        self._cancel = CancelResponse.ACCEPT
        self.handle = ActionServer(node, FollowJointTrajectory, action, execute_callback=self.execute,
                                   goal_callback=self.on_goal, cancel_callback=lambda _goal: self._cancel)

    def on_goal(self, goal: Any) -> Any:
        from rclpy.action import GoalResponse

        self.goals += 1
        names = list(goal.trajectory.joint_names)
        if sorted(names) != sorted(self.arm.joints) or len(set(names)) != len(names):
            self.node.get_logger().warning(f"{self.action}: rejected a goal for joints {names}; this controller "
                                           f"drives {list(self.arm.joints)}")
            return GoalResponse.REJECT
        if self.server.faults.trajectory_fault(self.server.trajectory_goals() + 1) == "reject":
            self.server.count_goal()
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def execute(self, handle: Any) -> Any:
        from control_msgs.action import FollowJointTrajectory
        from trajectory_msgs.msg import JointTrajectoryPoint

        Result = FollowJointTrajectory.Result
        number = self.server.count_goal()
        if number == 1:
            print(f"bt-meta sim: first goal on {self.action}", file=sys.stderr, flush=True)
        trajectory = handle.request.trajectory
        names = list(trajectory.joint_names)
        sim = self.server.sim
        fault = self.server.faults.trajectory_fault(number)
        if fault is not None and fault.startswith("abort"):
            code = int(fault.partition(":")[2] or Result.GOAL_TOLERANCE_VIOLATED)
            handle.abort()
            return Result(error_code=code, error_string=f"fault injected by --fault: goal {number} aborted")
        if not trajectory.points:
            handle.abort()
            return Result(error_code=Result.INVALID_GOAL, error_string="the trajectory has no points")
        previous = 0.0
        for index, point in enumerate(trajectory.points):
            at = duration_seconds(point.time_from_start)
            if len(point.positions) != len(names) or at < previous:
                handle.abort()
                return Result(error_code=Result.INVALID_GOAL,
                              error_string=f"point {index}: {len(point.positions)} positions for {len(names)} joints "
                                           f"at {at:.3f} s (times must not decrease)")
            if handle.is_cancel_requested:
                handle.canceled()
                return Result(error_code=Result.SUCCESSFUL, error_string="cancelled")
            steps = round((at - previous) / sim.time_step)
            target = {name: float(value) for name, value in zip(names, point.positions, strict=True)}
            self.server.drive(target, steps)
            previous = at
            actual = sim.joint_positions(names)
            feedback = FollowJointTrajectory.Feedback(joint_names=names)
            feedback.header.stamp = self.server.publishers.stamp()
            feedback.desired = point
            feedback.actual = JointTrajectoryPoint(positions=[actual[n] for n in names],
                                                   time_from_start=to_duration(at))
            feedback.error = JointTrajectoryPoint(positions=[target[n] - actual[n] for n in names],
                                                  time_from_start=to_duration(at))
            if not self.server.faults.no_feedback:
                handle.publish_feedback(feedback)
        handle.succeed()
        return Result(error_code=Result.SUCCESSFUL, error_string="")
