"""The service leaf (BehaviorTree.ROS2's ``RosServiceNode``): sends a request built from its ports, stays RUNNING
until the response, and turns the response into SUCCESS or FAILURE.

1. the service is not there yet (after the first tick's ``wait_for_server_timeout``): RUNNING; still absent
   ``server_timeout`` after the first tick: FAILURE, ``SERVICE_UNREACHABLE``, naming the service and the timeout
2. sent: RUNNING until the response; none within ``server_timeout``: ``SERVICE_TIMEOUT``
3. answered: the output ports are written and ``success_if`` (if any) decides

ROS 2 has no cancel for a request: a halt drops the pending response.

Offers:

* :class:`RosServiceLeaf`
"""

from __future__ import annotations

from typing import Any

from py_trees.common import Status

from bt_meta.bt.failures import FailureKind
from bt_meta.ros2.leaves.base import RosLeaf
from bt_meta.ros2.leaves.runtime import Pending

__all__ = ["RosServiceLeaf"]


class RosServiceLeaf(RosLeaf):
    def initialise(self) -> None:
        super().initialise()
        self.phase = "start"
        self.name_now = ""
        self.client: Any = None
        self.request: Any = None
        self.sent_at = 0.0
        self.response: Pending | None = None

    def update(self) -> Status:
        try:
            return self._step()
        except ValueError as error:
            return self.fail("INVALID_REQUEST", str(error), kind=FailureKind.INTERNAL, name=self.name_now or None)

    def _step(self) -> Status:
        if self.phase == "start":
            self.name_now = self.ros_name()
            self.request = self.fill(self.spec.interface.Request)
            self.client = self.connect(self.name_now)
            if not self.client.service_is_ready():
                self.client.wait_for_service(timeout_sec=self.milliseconds("wait_for_server_timeout"))
            self.phase = "server"
        timeout = self.milliseconds("server_timeout")
        if self.phase == "server":
            if not self.client.service_is_ready():
                if self.elapsed() < timeout:
                    return Status.RUNNING
                return self.fail("SERVICE_UNREACHABLE", f"no service {self.name_now} ({self.spec.type_name}) "
                                 f"within server_timeout {self.value('server_timeout')} ms",
                                 kind=FailureKind.INTERNAL, name=self.name_now)
            client, request = self.client, self.request
            self.response = self.shared().call(lambda: client.call_async(request))
            self.sent_at = self.elapsed()
            self.phase = "sent"
        assert self.response is not None
        if not self.response.done:
            if self.elapsed() - self.sent_at < timeout:
                return Status.RUNNING
            return self.fail("SERVICE_TIMEOUT", f"{self.name_now} did not respond within server_timeout "
                             f"{self.value('server_timeout')} ms", kind=FailureKind.INTERNAL, name=self.name_now)
        self.phase = "done"
        if self.response.error is not None:
            return self.fail("SERVICE_ABORTED", f"{self.name_now}: the call failed: {self.response.error}",
                             kind=FailureKind.INTERNAL, name=self.name_now)
        return self.finish(self.response.value, self.name_now, f"{self.name_now} responded")

    def connect(self, name: str) -> Any:
        interface = self.spec.interface
        shared = self.shared()
        return shared.entity(("service", self.spec.type_name, name),
                             lambda: shared.node.create_client(interface, name))

    def halt(self) -> None:
        self.phase = "halted"
        self.response = None
