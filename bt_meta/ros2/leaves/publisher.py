"""The topic-publisher condition (BehaviorTree.ROS2's ``RosTopicPubNode``): publishes a message built from its
ports and succeeds; a port value that does not fit its field is FAILURE and nothing is published.

One publisher per topic and type is shared by the process (queue of one, as BT.ROS2's). As with any ROS 2
publisher, a message published before a subscriber was discovered is not delivered to it.

Offers:

* :class:`RosPublisherLeaf`
"""

from __future__ import annotations

from typing import Any

from py_trees.common import Status

from bt_meta.bt.failures import FailureKind
from bt_meta.ros2.leaves.base import RosLeaf

__all__ = ["RosPublisherLeaf"]


class RosPublisherLeaf(RosLeaf):
    def update(self) -> Status:
        name = None
        try:
            name = self.ros_name()
            message = self.fill(self.spec.interface)
        except ValueError as error:
            return self.fail("INVALID_MESSAGE", str(error), kind=FailureKind.INTERNAL, name=name)
        self.connect(name).publish(message)
        return Status.SUCCESS

    def connect(self, name: str) -> Any:
        shared = self.shared()
        interface = self.spec.interface
        return shared.entity(("publisher", self.spec.type_name, name),
                             lambda: shared.node.create_publisher(interface, name, 1))
