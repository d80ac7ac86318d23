"""The action leaf (BehaviorTree.ROS2's ``RosActionNode``): sends a goal built from its ports, stays RUNNING while
the server works, and turns the result into SUCCESS or FAILURE; halted, it cancels its goal.

Per tick, never blocking but for the first tick's bounded wait for discovery (``wait_for_server_timeout``, as
BT.ROS2 waits when it creates its client):

1. the server is not there yet: RUNNING; still absent ``server_timeout`` after the first tick: FAILURE,
   ``SERVER_UNREACHABLE``, naming the action and the timeout
2. the goal was sent: RUNNING until the server answers; no answer within ``server_timeout``:
   ``SEND_GOAL_TIMEOUT``; refused: ``GOAL_REJECTED_BY_SERVER``
3. accepted: RUNNING until the result; aborted / canceled by the server: ``ACTION_ABORTED`` /
   ``ACTION_CANCELLED``; succeeded: the output ports are written and ``success_if`` (if any) decides

A halt while a goal runs asks the server to cancel it and waits up to ``server_timeout`` for the answer.

Offers:

* :class:`RosActionLeaf`
"""

from __future__ import annotations

from typing import Any

from py_trees.common import Status

from bt_meta.bt.failures import FailureKind
from bt_meta.ros2.leaves.base import RosLeaf
from bt_meta.ros2.leaves.runtime import Pending

__all__ = ["RosActionLeaf"]


class RosActionLeaf(RosLeaf):
    _watched = False

    def initialise(self) -> None:
        super().initialise()
        self.phase = "start"
        self.name_now = ""
        self.client: Any = None
        self.goal: Any = None
        self.sent_at = 0.0
        self.response: Pending | None = None
        self.result: Pending | None = None
        self.handle: Any = None

    def update(self) -> Status:
        try:
            return self._step()
        except ValueError as error:  # a port that does not convert, an empty name
            return self.fail("INVALID_GOAL", str(error), kind=FailureKind.INTERNAL, name=self.name_now or None)

    def _step(self) -> Status:
        if self.phase == "start":
            self.name_now = self.ros_name()
            self.goal = self.fill(self.spec.interface.Goal)
            self.client = self.connect(self.name_now)
            if not self.client.server_is_ready():
                self.client.wait_for_server(timeout_sec=self.milliseconds("wait_for_server_timeout"))
            self.phase = "server"
        timeout = self.milliseconds("server_timeout")
        if self.phase == "server":
            if not self.client.server_is_ready():
                if self.elapsed() < timeout:
                    return Status.RUNNING
                return self.fail("SERVER_UNREACHABLE", f"no action server {self.name_now} "
                                 f"({self.spec.type_name}) within server_timeout {self.value('server_timeout')} ms",
                                 kind=FailureKind.INTERNAL, name=self.name_now)
            client, goal = self.client, self.goal
            shared = self.shared()
            self.response = shared.call(lambda: client.send_goal_async(goal))
            if not self._watched:  # a goal still running when the process ends is cancelled
                shared.on_close(self._halt_at_close)
                self._watched = True
            self.sent_at = self.elapsed()
            self.phase = "sent"
        if self.phase == "sent":
            assert self.response is not None
            if not self.response.done:
                if self.elapsed() - self.sent_at < timeout:
                    return Status.RUNNING
                return self.fail("SEND_GOAL_TIMEOUT", f"{self.name_now} did not answer the goal within "
                                 f"server_timeout {self.value('server_timeout')} ms", kind=FailureKind.INTERNAL,
                                 name=self.name_now)
            if self.response.error is not None:
                return self.fail("SEND_GOAL_TIMEOUT", f"{self.name_now}: sending the goal failed: "
                                 f"{self.response.error}", kind=FailureKind.INTERNAL, name=self.name_now)
            handle = self.handle = self.response.value
            if not handle.accepted:
                return self.fail("GOAL_REJECTED_BY_SERVER", f"{self.name_now} rejected the goal",
                                 name=self.name_now, rejected=True)
            self.result = self.shared().call(handle.get_result_async)
            self.phase = "running"
        assert self.result is not None
        if not self.result.done:
            return Status.RUNNING
        if self.result.error is not None:
            return self.fail("ACTION_ABORTED", f"{self.name_now}: no result: {self.result.error}",
                             kind=FailureKind.INTERNAL, name=self.name_now)
        return self._result(self.result.value)

    def _result(self, wrapped: Any) -> Status:
        from action_msgs.msg import GoalStatus

        self.phase = "done"
        if wrapped.status == GoalStatus.STATUS_ABORTED:
            return self.fail("ACTION_ABORTED", f"{self.name_now} aborted the goal", name=self.name_now,
                             status="ABORTED")
        if wrapped.status == GoalStatus.STATUS_CANCELED:
            return self.fail("ACTION_CANCELLED", f"{self.name_now} canceled the goal", name=self.name_now,
                             status="CANCELED")
        return self.finish(wrapped.result, self.name_now, f"{self.name_now} succeeded")

    def connect(self, name: str) -> Any:
        from rclpy.action import ActionClient

        interface = self.spec.interface
        shared = self.shared()
        return shared.entity(("action", self.spec.type_name, name),
                             lambda: ActionClient(shared.node, interface, name))

    def halt(self) -> None:
        """Cancel the goal in flight (one accepted, or one whose answer is still coming) and wait for the answer."""
        try:
            timeout = self.milliseconds("server_timeout")
        except Exception:  # its blackboard entry is gone: the registered default
            timeout = self.spec.server_timeout / 1000.0
        if self.phase == "sent" and self.response is not None and self.response.wait(timeout) \
                and self.response.error is None and self.response.value.accepted:
            self.handle = self.response.value
            self.phase = "running"
        if self.phase != "running" or self.handle is None:
            return
        handle = self.handle
        cancel = self.shared().call(handle.cancel_goal_async)
        if not cancel.wait(timeout):
            self.feedback_message = f"{self.spec.id}: {self.name_now} did not answer the cancel request within " \
                                    f"{timeout * 1000:g} ms"
        self.phase = "halted"

    def _halt_at_close(self) -> None:
        if self.phase in ("sent", "running"):
            self.halt()
