"""Action clients of the ROS 2 world: a FollowJointTrajectory goal or a GripperCommand sent and waited for, with
the timeouts of the config; a rejected or aborted goal raised as :class:`GoalFailed` with the error code, a result
that never comes as :class:`~bt_meta.ros2.errors.ConnectionLost`. Goals still running are cancelled by
:meth:`ActionClient.cancel_active` (the world does it on the way out: Ctrl-C, a lost connection).

Feedback is counted: succeeded trajectory goals that never got any feedback point at interface definitions of
another distro (goals and results still work then, feedback is silently dropped; docs/ros2.md), and
:meth:`TrajectoryClient.feedback_missing` says so.

Offers:

* :class:`GoalFailed` -- rejected (``code`` ``None``) or aborted (``code``, ``text`` from the result)
* :class:`ActionClient` -- ``wait_for_server``, ``cancel_active``; :class:`TrajectoryClient` -- ``follow``;
  :class:`GripperClient` -- ``command``
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Sequence
from typing import Any

from bt_meta.errors import BtMetaError
from bt_meta.ros2.errors import ConnectionLost
from bt_meta.ros2.messages import to_duration

__all__ = ["ActionClient", "GoalFailed", "GripperClient", "TrajectoryClient"]

FEEDBACK_BOUND = 10
"""Succeeded trajectory goals without a single feedback message after which a definitions mismatch is named."""


class GoalFailed(BtMetaError):
    def __init__(self, action: str, code: int | None, text: str) -> None:
        self.action = action
        self.code = code
        self.text = text
        what = "rejected the goal" if code is None else f"aborted the goal with error code {code}"
        super().__init__(f"{action} {what}" + (f": {text}" if text else ""))


def _wait(future: Any, timeout: float) -> bool:
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    return done.wait(timeout)


class ActionClient:
    """Requests are made on the executor's thread (:meth:`_on_executor`): rclpy's action client registers a
    request after sending it, and a response taken by the executor in between is dropped ("Ignoring unexpected
    goal response"), which a request from another thread made happen within a few goals."""

    def __init__(self, node: Any, kind: Any, action: str, executor: Any, callback_group: Any = None) -> None:
        from rclpy.action import ActionClient as RclpyActionClient

        self.action = action
        self.executor = executor
        self.client = RclpyActionClient(node, kind, action, callback_group=callback_group)
        self._active: list[Any] = []
        self._lock = threading.Lock()

    def wait_for_server(self, timeout: float) -> bool:
        return bool(self.client.wait_for_server(timeout_sec=timeout))

    def _on_executor(self, make: Any, timeout: float, what: str) -> Any:
        """The future ``make()`` returns when called on the executor's thread, once done; else ConnectionLost."""
        made: list[Any] = []
        ready = threading.Event()

        def request() -> None:
            made.append(make())
            made[0].add_done_callback(lambda _f: ready.set())

        self.executor.create_task(request)
        if not ready.wait(timeout):
            raise ConnectionLost(f"{self.action}: {what} within {timeout:g} s")
        return made[0].result()

    def _send(self, goal: Any, timeout: float, feedback: Any = None) -> Any:
        handle = self._on_executor(lambda: self.client.send_goal_async(goal, feedback_callback=feedback), timeout,
                                   "no answer to a goal")
        if not handle.accepted:
            raise GoalFailed(self.action, None, "")
        with self._lock:
            self._active.append(handle)
        try:
            return self._on_executor(handle.get_result_async, timeout, "no result")
        finally:
            with self._lock:
                self._active.remove(handle)

    def cancel_active(self, timeout: float = 1.0) -> int:
        """Ask every goal still running to cancel (waiting up to ``timeout`` each); returns how many were asked."""
        with self._lock:
            handles = list(self._active)
        for handle in handles:
            with contextlib.suppress(ConnectionLost):
                self._on_executor(handle.cancel_goal_async, timeout, "no answer to a cancel request")
        return len(handles)


class TrajectoryClient(ActionClient):
    def __init__(self, node: Any, action: str, joints: Sequence[str], executor: Any, callback_group: Any = None
                 ) -> None:
        from control_msgs.action import FollowJointTrajectory

        super().__init__(node, FollowJointTrajectory, action, executor, callback_group)
        self.joints = tuple(joints)
        self.succeeded = 0
        self.feedback = 0
        self.tap: Any = None
        """``tap(topic, trajectory)`` sees every trajectory sent (the MCAP recording), else ``None``."""

    def follow(self, points: Sequence[tuple[Sequence[float], float]], timeout: float) -> Any:
        """Execute ``(positions in joint order, seconds from start)`` points; the result, or raise."""
        from control_msgs.action import FollowJointTrajectory
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        trajectory = JointTrajectory(joint_names=list(self.joints), points=[
            JointTrajectoryPoint(positions=[float(v) for v in positions], time_from_start=to_duration(at))
            for positions, at in points])
        if self.tap is not None:
            self.tap(f"{self.action}/goal_trajectory", trajectory)
        wrapped = self._send(FollowJointTrajectory.Goal(trajectory=trajectory), timeout, self._on_feedback)
        result = wrapped.result
        if result.error_code != FollowJointTrajectory.Result.SUCCESSFUL or wrapped.status != _succeeded():
            raise GoalFailed(self.action, int(result.error_code), str(result.error_string))
        self.succeeded += 1
        return result

    def _on_feedback(self, _message: Any) -> None:
        self.feedback += 1

    def feedback_missing(self) -> bool:
        return self.feedback == 0 and self.succeeded >= FEEDBACK_BOUND


class GripperClient(ActionClient):
    def __init__(self, node: Any, action: str, executor: Any, callback_group: Any = None) -> None:
        from control_msgs.action import GripperCommand

        super().__init__(node, GripperCommand, action, executor, callback_group)

    def command(self, position: float, max_effort: float, timeout: float) -> Any:
        from control_msgs.action import GripperCommand

        goal = GripperCommand.Goal()
        goal.command.position = float(position)
        goal.command.max_effort = float(max_effort)
        wrapped = self._send(goal, timeout)
        if wrapped.status != _succeeded():
            raise GoalFailed(self.action, None if wrapped.status != _aborted() else -1, "gripper command failed")
        return wrapped.result


def _succeeded() -> int:
    from action_msgs.msg import GoalStatus

    return GoalStatus.STATUS_SUCCEEDED


def _aborted() -> int:
    from action_msgs.msg import GoalStatus

    return GoalStatus.STATUS_ABORTED
