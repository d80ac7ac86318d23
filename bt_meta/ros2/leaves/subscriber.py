"""The topic-subscriber condition (BehaviorTree.ROS2's ``RosTopicSubNode``): SUCCESS or FAILURE from the latest
message on a topic.

One subscription per topic and type is shared by every leaf of the process (queue of one, as BT.ROS2's); each
leaf keeps the last message it was given. A tick with no message since the previous tick is FAILURE, as BT.ROS2's
``onTick(nullptr)`` usually answers; with ``latch: true`` the last message stays until a newer one arrives. With a
message, the output ports are written and ``success_if`` (if any) decides.

Offers:

* :class:`RosSubscriberLeaf`
"""

from __future__ import annotations

import threading
from typing import Any

from py_trees.common import Status

from bt_meta.bt.failures import FailureKind
from bt_meta.ros2.leaves.base import RosLeaf

__all__ = ["RosSubscriberLeaf"]


class _Shared:
    """A subscription and the leaves listening to it (every message is handed to each)."""

    def __init__(self) -> None:
        self.listeners: list[RosSubscriberLeaf] = []
        self.lock = threading.Lock()
        self.subscription: Any = None

    def received(self, message: Any) -> None:
        with self.lock:
            for leaf in self.listeners:
                leaf.last = message


class RosSubscriberLeaf(RosLeaf):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.last: Any = None
        self.topic: str | None = None
        super().__init__(*args, **kwargs)

    def update(self) -> Status:
        try:
            name = self.ros_name()
        except ValueError as error:
            return self.fail("INVALID_TOPIC", str(error), kind=FailureKind.INTERNAL)
        if self.topic != name:
            self.connect(name)
        message, self.last = self.last, (self.last if self.spec.latch else None)
        if message is None:
            return self.fail("NO_MESSAGE", f"no message on {name} since the last tick", name=name)
        return self.finish(message, name, f"message on {name}")

    def connect(self, name: str) -> Any:
        shared = self.shared()
        interface = self.spec.interface

        def make() -> _Shared:
            listeners = _Shared()
            listeners.subscription = shared.node.create_subscription(interface, name, listeners.received, 1)
            return listeners

        listeners = shared.entity(("subscription", self.spec.type_name, name), make)
        with listeners.lock:
            if self.topic is not None:  # a {key} name that changed: stop listening to the old topic
                shared.entity(("subscription", self.spec.type_name, self.topic), _Shared).listeners.remove(self)
            listeners.listeners.append(self)
        self.topic = name
        return listeners
